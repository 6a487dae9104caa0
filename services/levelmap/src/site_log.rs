//! `levelmap site-log rebuild`: a cluster site's log written anew from a host's store, for a
//! log that is lost (docs/cluster.md, "A site's log lost"). The store is read only: a stopped
//! host's own, or a backup of a running one (`levelmap backup`).

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use std::path::PathBuf;

/// A cluster site's log (docs/cluster.md).
#[derive(Args, Debug)]
pub struct SiteLogArgs {
    #[command(subcommand)]
    command: SiteLogCommand,
}

#[derive(Subcommand, Debug)]
enum SiteLogCommand {
    Rebuild(RebuildArgs),
}

/// Write a site's lost log anew from a host's store: its nodes, edges, solves, spans,
/// versions and modes, in a new stream that every host's store reads from its start. Holds
/// the site's lease while it writes; the site's robots re-send what the store lacks.
#[derive(Args, Debug)]
struct RebuildArgs {
    /// The site.
    site: String,
    /// A cluster host's TOML configuration: its `[cluster]` (the NATS servers, its name and
    /// credentials) and, without --store, its store_path.
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// The store to read: a backup of a running host (`levelmap backup`), or a stopped
    /// host's store file. Default: the config's store_path (its mapper stopped).
    #[arg(long, value_name = "FILE")]
    store: Option<PathBuf>,
    /// Delete the site's log even though it holds records, and write the store's in its
    /// place (a log made empty again by a host is replaced without it).
    #[arg(long)]
    replace: bool,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(args: &SiteLogArgs) -> Result<()> {
    match &args.command {
        SiteLogCommand::Rebuild(args) => rebuild(args),
    }
}

fn rebuild(args: &RebuildArgs) -> Result<()> {
    let config = mapper::MapperConfig::load(Some(&args.config))?;
    let Some(cluster) = &config.cluster else {
        bail!(
            "{}: no [cluster] table; a site's log is a cluster host's",
            args.config.display()
        );
    };
    let path = args.store.as_ref().unwrap_or(&config.store_path);
    if !path.exists() {
        bail!("{}: no such store", path.display());
    }
    let store = mapper::store::Store::open(path).with_context(|| {
        format!(
            "{}: not opened (a running mapper holds its store: take a backup with `levelmap \
             backup` and pass it as --store)",
            path.display()
        )
    })?;
    let runtime = crate::services::runtime()?;
    let progress = |line: &str| eprintln!("site-log rebuild: {line}");
    let report = runtime.block_on(cluster::rebuild::rebuild(
        cluster,
        &store,
        &args.site,
        args.replace,
        &progress,
    ))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        let h = &report.holds;
        println!(
            "site {}: {} records appended at {}–{} in {:.1} s ({} nodes, {} edges, {} solves, \
             {} spans, {} versions, {} mode changes)",
            report.site,
            report.records,
            report.first_sequence,
            report.last_sequence,
            report.seconds,
            h.nodes,
            h.edges,
            h.solves,
            h.spans,
            h.versions,
            h.modes
        );
    }
    Ok(())
}
