//! `levelmap mapper`, `levelmap gateway` and `levelmap edge`: the services, run until Ctrl-C.

use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

/// Run the mapping server: Zenoh router for the robots, durable store, HTTP API.
#[cfg(feature = "mapper")]
#[derive(Args, Debug)]
pub struct MapperArgs {
    /// TOML configuration (see deploy/mapper.toml); defaults without one. Environment
    /// variables set keys too: LEVELMAP_HTTP_LISTEN, LEVELMAP_ZENOH__LISTEN (nested: __).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Also feed this recording (`levelmap record`) to the map: its nodes and odometry, in
    /// recorded order, as fast as the mapper takes them, then one solve per fleet. Zenoh
    /// stays open for robots meanwhile.
    #[arg(long, value_name = "FILE.mcap")]
    pub from_recording: Option<PathBuf>,
    /// With --from-recording: stop once it is fed and solved, instead of serving on.
    #[arg(long, requires = "from_recording")]
    pub exit_when_done: bool,
    /// Check the store (of a stopped mapper: redb opens a file once) and exit, serving
    /// nothing: every fleet replayed from all of its nodes, its snapshot ignored; the replay's
    /// edges compared with the stored ones, and what the fleet's snapshot restores (snapshot
    /// and the nodes after it) compared with the replay, bit for bit. Exit code 0 when all
    /// of it matches, 1 otherwise.
    #[arg(long, conflicts_with = "from_recording")]
    pub verify_store: bool,
    /// Start from a backup (`levelmap backup`): the file is checked (it opens as a store)
    /// and put in place as the config's store_path, which must not exist. The robots'
    /// outboxes then bring back the nodes acked after the backup (docs/services.md,
    /// "Backup and restore").
    #[arg(long, value_name = "BACKUP.redb", conflicts_with = "verify_store")]
    pub restore: Option<PathBuf>,
    /// With --verify-store: print the report as JSON.
    #[arg(long, requires = "verify_store")]
    pub json: bool,
}

/// Run a cluster's stateless HTTP gateway: each site's requests to the mapper host that
/// owns it, as the leases in NATS say (docs/cluster.md).
#[cfg(feature = "mapper")]
#[derive(Args, Debug)]
pub struct GatewayArgs {
    /// TOML configuration (see deploy/cluster/gateway.toml). Environment variables set keys
    /// too: LEVELMAP_HTTP_LISTEN, LEVELMAP_NATS__SERVERS (nested: __).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
}

/// Run a robot's edge service: its source's scans leveled and published as nodes.
#[cfg(feature = "edge")]
#[derive(Args, Debug)]
pub struct EdgeArgs {
    /// TOML configuration (see deploy/edge.toml); defaults without one. Environment
    /// variables set keys too: LEVELMAP_ROBOT, LEVELMAP_ZENOH__CONNECT (nested: __).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Print the final report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Zenoh needs Tokio's multi-thread runtime (and so does the NATS client of `site-log`).
pub(crate) fn runtime() -> Result<tokio::runtime::Runtime> {
    Ok(tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?)
}

fn init_logging() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
}

#[cfg(feature = "mapper")]
pub fn run_mapper(args: &MapperArgs) -> Result<()> {
    init_logging();
    let config = mapper::MapperConfig::load(args.config.as_deref())?;
    if args.verify_store {
        return verify_store(&config, args.json);
    }
    if let Some(backup) = &args.restore {
        let put = mapper::store::restore_backup(backup, &config.store_path)?;
        let fleets: Vec<String> = put.fleets.iter().map(|(f, n)| format!("{f}={n}")).collect();
        tracing::info!(
            bytes = put.bytes,
            "{} restored as {} (nodes: {})",
            backup.display(),
            config.store_path.display(),
            fleets.join(", ")
        );
    }
    // A bad Zenoh or TLS setting stops the mapper here, before its store is opened.
    let zenoh = config.zenoh.to_zenoh(runtime::session::Role::Router)?;
    let listen = zenoh.get_json("listen/endpoints").unwrap_or_default();
    runtime()?.block_on(async {
        let stop = runtime::session::shutdown_signal();
        // One mapper either way: alone, or deployed as one host of a cluster.
        let running = match config.cluster {
            None => mapper::start(config.clone()).await?,
            Some(_) => cluster::start(config.clone()).await?,
        };
        tracing::info!(
            "mapper: Zenoh {listen}, HTTP http://{}/api/v1, store {}",
            running.http_addr,
            config.store_path.display()
        );
        let foxglove = match config.foxglove.enabled {
            true => {
                let tokens = mapper::tokens::Tokens::new(&config.token, &config.read_token);
                let (shared, clouds) = (running.shared.clone(), running.clouds.clone());
                Some(foxglove_feed::start(&config.foxglove, tokens, shared, clouds).await?)
            }
            false => None,
        };
        if let Some(path) = &args.from_recording {
            let fed = running.feed_recording(path).await;
            match &fed {
                Ok(report) => {
                    tracing::info!(
                        messages = report.messages,
                        nodes = report.nodes,
                        odometry = report.odometry,
                        live_scans = report.live_scans,
                        ignored = report.ignored,
                        solves = report.solves,
                        "{}: fed",
                        path.display()
                    );
                    for (fleet, solve) in &report.last_solve {
                        tracing::info!(fleet, "last solve: {solve}");
                    }
                }
                Err(e) => tracing::error!("{e:#}"),
            }
            if fed.is_err() || args.exit_when_done {
                if let Some(feed) = foxglove {
                    feed.stop().await;
                }
                running.stop().await?;
                return fed.map(|_| ());
            }
        }
        stop.await;
        tracing::info!("stopping");
        if let Some(feed) = foxglove {
            feed.stop().await;
        }
        running.stop().await
    })
}

#[cfg(feature = "mapper")]
pub fn run_gateway(args: &GatewayArgs) -> Result<()> {
    init_logging();
    let config = gateway::GatewayConfig::load(args.config.as_deref())?;
    runtime()?.block_on(async {
        let stop = runtime::session::shutdown_signal();
        let running = gateway::start(config.clone()).await?;
        tracing::info!(
            "gateway: HTTP http://{}/api/v1 for hosts {:?}",
            running.http_addr,
            config.hosts.keys().collect::<Vec<_>>()
        );
        stop.await;
        tracing::info!("stopping");
        running.stop().await
    })
}

/// `levelmap mapper --verify-store`: the report, and exit code 1 unless all of it matched.
#[cfg(feature = "mapper")]
fn verify_store(config: &mapper::MapperConfig, json: bool) -> Result<()> {
    let path = &config.store_path;
    anyhow::ensure!(path.exists(), "{}: no store there", path.display());
    let store = mapper::Store::open(path)
        .map_err(|e| anyhow::anyhow!("{}: cannot open the store: {e}", path.display()))?;
    let check = mapper::restore::verify_store(config, &store)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&check)?);
    } else {
        println!(
            "store {} (format {}), running {}",
            path.display(),
            check.format,
            check.mapping_version
        );
        for f in &check.fleets {
            let replay = match (&f.replay_error, &f.edges_differ) {
                (Some(e), _) => format!("DOES NOT REPLAY (a start quarantines it): {e}"),
                (None, None) => "replays to the stored edges".to_owned(),
                (None, Some(d)) => d.clone(),
            };
            println!(
                "fleet {}: {} nodes, {} edges, {} solves: {replay} ({:.0} ms)",
                f.fleet, f.nodes, f.edges, f.solves, f.replay_ms
            );
            let mapped_by = f.mapping_version.as_deref().unwrap_or("no mapping version");
            match &f.rebuild {
                Some(why) => println!("  a start REBUILDS it from its nodes: {why}"),
                None => println!("  mapped by {mapped_by}: a start restores it"),
            }
            let snapshot = match &f.snapshot {
                None => "no snapshot".to_owned(),
                Some(s) => match (&s.error, s.differences.is_empty()) {
                    (Some(e), _) => format!("snapshot ({} bytes) NOT USABLE: {e}", s.bytes),
                    (None, true) => format!(
                        "snapshot of {} nodes ({} bytes) restores the replay exactly ({:.0} ms)",
                        s.covers, s.bytes, s.restore_ms
                    ),
                    (None, false) => format!(
                        "snapshot of {} nodes ({} bytes) DIFFERS from the replay: {}",
                        s.covers,
                        s.bytes,
                        s.differences.join(", ")
                    ),
                },
            };
            println!("  {snapshot}");
        }
        println!("{}", if check.ok { "ok" } else { "FAILED" });
    }
    if !check.ok {
        std::process::exit(1);
    }
    Ok(())
}

#[cfg(feature = "edge")]
pub fn run_edge(args: &EdgeArgs) -> Result<()> {
    init_logging();
    let config = edge::EdgeConfig::load(args.config.as_deref())?;
    // The link is retried while the mapper is out of reach; a bad Zenoh or TLS setting must
    // stop the service instead.
    config.zenoh.to_zenoh(runtime::session::Role::Client)?;
    let report = runtime()?.block_on(async {
        let stop = runtime::session::shutdown_signal();
        let source = edge::open_source(&config, runtime::session::now_ns())?;
        edge::run(config, source, stop).await
    })?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "{}: {} nodes, {} sends ({} re-sends, {} sessions reopened), acked up to {:?}, {} \
             waiting in the outbox",
            report.robot,
            report.nodes,
            report.node_sends,
            report.node_resends,
            report.link_reopens,
            report.acked_node_seq,
            report.outbox_pending
        );
    }
    Ok(())
}
