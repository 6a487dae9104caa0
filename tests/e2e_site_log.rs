//! A cluster site's log lost and rebuilt from a host's store: two mapper hosts (h1, h2) on
//! loopback over three nats-servers, two robots publishing to site `park`. A backup of the
//! owner is taken while they drive (`levelmap backup`), more nodes are acked after it, then
//! the site's stream is deleted: its log is gone with every record. The site stops acking
//! (the robots keep their nodes); `levelmap site-log rebuild park --store BACKUP` writes the
//! log anew from the backup; the site maps again, and the robots' outboxes bring back what
//! the backup lacks. At the end each robot's nodes are 0..made, once, in order, on the host
//! serving the site; then that host is killed and the other, whose store followed the old log
//! and then found the rebuilt one, takes the site over with every node.

mod common;

#[path = "../services/sitelog/tests/common/servers.rs"]
mod nats;

use common::*;
use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

const HOSTS: [&str; 2] = ["h1", "h2"];
const ROBOTS: usize = 2;
const TOKEN: &str = "site-log-drill-token";

fn nodes(http: &str) -> Option<u64> {
    get_json(http, "/api/v1/fleets/park/summary")?["nodes"].as_u64()
}

/// The host serving the site and its map's nodes.
fn serving(hosts: &[Option<MapperProcess>]) -> Option<(usize, u64)> {
    hosts
        .iter()
        .enumerate()
        .find_map(|(h, p)| Some((h, nodes(&p.as_ref()?.http)?)))
}

/// Nodes acked by every running host so far.
fn acks(hosts: &[Option<MapperProcess>]) -> u64 {
    hosts
        .iter()
        .flatten()
        .map(|h| {
            let metrics = http_get(&h.http, "/metrics").expect("metrics").1;
            metric(&metrics, "levelmap_node_ack_seconds_count")
        })
        .sum()
}

fn robots(dir: &Path, routers: &[&str]) -> Vec<KillOnDrop> {
    (0..ROBOTS)
        .map(|r| {
            let source = format!("[source.sim]\nloop_index = {r}\nduration_s = 160.0\n");
            edge_command_to(dir, r, routers, 4.0, &source)
                .stdout(Stdio::piped())
                .stderr(Stdio::null())
                .spawn()
                .map(KillOnDrop::from)
                .expect("levelmap edge starts")
        })
        .collect()
}

#[test]
fn a_sites_lost_log_rebuilt_from_a_backup_loses_no_node() {
    let dir = temp_dir("site-log-rebuild");
    let servers = nats::Cluster::start("site-log-rebuild", None);
    let urls = servers.client_urls();
    let zenoh: Vec<String> = HOSTS
        .iter()
        .map(|_| format!("tcp/127.0.0.1:{}", free_port()))
        .collect();
    let mut hosts: Vec<Option<MapperProcess>> = Vec::new();
    for (h, name) in HOSTS.iter().enumerate() {
        let host_dir = dir.join(name);
        std::fs::create_dir_all(&host_dir).expect("the host's folder");
        let router = (zenoh[h].as_str(), &zenoh[..h]);
        let toml = cluster_host_config(&host_dir, (name, &HOSTS), TOKEN, router, &urls);
        hosts.push(Some(MapperProcess::start_config(
            &host_dir,
            zenoh[h].clone(),
            &toml,
        )));
    }
    let (owner, _) =
        wait_for(Duration::from_secs(60), || serving(&hosts)).expect("a host takes the site over");
    let owner_http = hosts[owner].as_ref().expect("running").http.clone();
    eprintln!("site-log: {} owns the site", HOSTS[owner]);
    let routers: Vec<&str> = zenoh.iter().map(String::as_str).collect();
    let edges = robots(&dir, &routers);
    wait_for(Duration::from_secs(90), || {
        (nodes(&owner_http)? >= 10).then_some(())
    })
    .expect("the robots' nodes reach the map");

    let backup = dir.join("backup.redb");
    let (_, in_backup) = backed_up(&common::backup(&owner_http, &backup, Some(TOKEN)));
    let acked_at_loss = wait_for(Duration::from_secs(60), || {
        let n = nodes(&owner_http)?;
        (n >= in_backup + 10).then_some(n)
    })
    .expect("nodes acked after the backup");

    // The log lost: its stream deleted with every record.
    let runtime = tokio::runtime::Runtime::new().expect("a runtime");
    runtime.block_on(async {
        let access = sitelog::NatsAccess {
            servers: urls.clone(),
            ..Default::default()
        };
        let js = access.jetstream("site-log-drill").await.expect("NATS");
        js.delete_stream("LEVELMAP_SITE_park")
            .await
            .expect("the site's stream deleted");
    });
    let lost = Instant::now();
    // Nothing is acked without the log, on any host, while the robots publish on.
    std::thread::sleep(Duration::from_secs(3));
    let stalled_at = acks(&hosts);
    std::thread::sleep(Duration::from_secs(5));
    let after_stall = acks(&hosts);
    eprintln!(
        "site-log: {in_backup} nodes in the backup, {acked_at_loss} acked when the log was lost; \
         the hosts had acked {stalled_at} nodes 3 s after the loss and {after_stall} 8 s after"
    );
    assert_eq!(after_stall, stalled_at, "the site acked without its log");

    let config = dir.join(HOSTS[owner]).join("mapper.toml");
    let rebuilt = levelmap()
        .args(["site-log", "rebuild", "park", "--json", "--config"])
        .arg(&config)
        .arg("--store")
        .arg(&backup)
        .output()
        .expect("levelmap site-log rebuild runs");
    let stderr = String::from_utf8_lossy(&rebuilt.stderr);
    assert!(rebuilt.status.success(), "{stderr}");
    eprint!("{stderr}");
    let report: serde_json::Value = serde_json::from_slice(&rebuilt.stdout).expect("JSON");
    eprintln!(
        "site-log: rebuilt {:.1} s after the loss: {report}",
        lost.elapsed().as_secs_f64()
    );
    assert_eq!(report["holds"]["nodes"], in_backup, "{report}");
    assert!(
        report["first_sequence"].as_u64().unwrap() > 1 << 32,
        "{report}"
    );
    // Refused on a log that holds records, without --replace.
    let again = levelmap()
        .args(["site-log", "rebuild", "park", "--config"])
        .arg(&config)
        .arg("--store")
        .arg(&backup)
        .output()
        .expect("levelmap site-log rebuild runs");
    assert!(!again.status.success());
    let why = String::from_utf8_lossy(&again.stderr);
    assert!(why.contains("--replace"), "{why}");

    let back = Instant::now();
    wait_for(Duration::from_secs(60), || {
        let (_, n) = serving(&hosts)?;
        (n > in_backup).then_some(())
    })
    .expect("the site maps again after the rebuild");
    eprintln!(
        "site-log: the site mapped again {:.1} s after the rebuild",
        back.elapsed().as_secs_f64()
    );
    let reports: Vec<_> = edges
        .into_iter()
        .map(|edge| edge_report(edge, Duration::from_secs(240)))
        .collect();
    let every_node_once = |http: &str| {
        let mut made_total = 0;
        for (r, report) in reports.iter().enumerate() {
            let made = report["nodes"].as_u64().expect("nodes");
            made_total += made;
            assert_eq!(report["outbox_pending"], 0, "robot{r}: {report}");
            let seqs = node_seqs(http, "park", &format!("robot{r}"));
            assert_eq!(
                seqs,
                (0..made).collect::<Vec<_>>(),
                "robot{r}: every node made, once, in order"
            );
        }
        made_total
    };
    let (now_owner, _) = serving(&hosts).expect("a host serves the site");
    let made = every_node_once(&hosts[now_owner].as_ref().expect("running").http);
    let in_map = nodes(&hosts[now_owner].as_ref().expect("running").http).expect("summary");
    eprintln!(
        "site-log: {made} nodes made, {in_map} in the map on {}, lost {}",
        HOSTS[now_owner],
        made - in_map
    );
    assert_eq!(in_map, made);

    // The other host's store followed the old log: it drops it on the rebuilt log's gap and
    // takes the site over from the new one, every node there.
    let other = 1 - now_owner;
    hosts[now_owner].take().expect("running").kill();
    let taken_over = Instant::now();
    let other_http = hosts[other].as_ref().expect("running").http.clone();
    wait_for(Duration::from_secs(60), || {
        (nodes(&other_http)? >= made).then_some(())
    })
    .expect("the other host takes the site over with every node");
    eprintln!(
        "site-log: {} took the site over {:.1} s after {}'s kill",
        HOSTS[other],
        taken_over.elapsed().as_secs_f64(),
        HOSTS[now_owner]
    );
    assert_eq!(every_node_once(&other_http), made);
    // The log itself holds every node once, by arrival, without a gap: a host with an empty
    // store would restore the whole site from it.
    let arrivals = runtime.block_on(async {
        let access = sitelog::NatsAccess {
            servers: urls.clone(),
            ..Default::default()
        };
        let js = access.jetstream("site-log-drill").await.expect("NATS");
        let retry = sitelog::RetryPolicy::default();
        let log = sitelog::SiteLog::open(js, "park", 3, retry)
            .await
            .expect("the log");
        let mut arrivals = Vec::new();
        for entry in log.read_from(1).await.expect("the log's records") {
            if let Ok(cluster::record::LogRecord::Batch(record)) =
                cluster::record::LogRecord::decode(&entry.payload)
            {
                arrivals.extend(record.nodes.iter().map(|(arrival, _)| *arrival));
            }
        }
        arrivals
    });
    assert_eq!(
        arrivals,
        (0..made).collect::<Vec<_>>(),
        "the log's nodes by arrival"
    );

    // Both stores held the old log (the owner's, and the standby's that followed it), and
    // both found the rebuilt one's gap.
    for h in HOSTS {
        let log = std::fs::read_to_string(dir.join(h).join("mapper.log")).unwrap_or_default();
        assert!(
            log.contains("the site's log was rebuilt"),
            "{h}'s store did not find the rebuilt log's gap"
        );
    }
    drop(hosts);
    drop(servers);
    std::fs::remove_dir_all(&dir).ok();
}
