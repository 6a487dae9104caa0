//! Cluster mode drills: two mapper hosts (h1, h2) on a three-node NATS JetStream cluster,
//! their Zenoh routers meshed, two robots on h2's router; h1 owns the site.
//! - h1 killed (SIGKILL) while the robots publish: h2 claims the site's lease once it
//!   lapses, reads the site's log into its own store and maps on;
//! - h1 frozen (SIGSTOP) past its lease, then let go: h2 takes the site; h1, awake, finds
//!   its lease lost or its append fenced and drops the site.
//!
//! In both, every node h1 had acked is in h2's map, and every node the robots made reaches
//! it exactly once. Checked through HTTP only.

mod common;

use common::netns::Netns;
#[path = "../services/sitelog/tests/common/servers.rs"]
mod nats;

use common::*;
use std::path::Path;
use std::time::{Duration, Instant};

const ROBOTS: usize = 2;

/// A mapper host's config: site `park`, hosts h1 and h2, its Zenoh listening and connecting,
/// the NATS servers at address `nats` on `ports`.
fn host_config(
    dir: &Path,
    host: &str,
    (zenoh, connect): (&str, Option<&str>),
    (nats, ports): (&str, &[u16]),
) -> String {
    let servers: Vec<String> = ports.iter().map(|p| format!("nats://{nats}:{p}")).collect();
    let connect = connect.map_or(String::new(), |c| format!("connect = [{c:?}]\n"));
    format!(
        "store_path = {store:?}\nfleets = [\"park\"]\n\
         [mapping.coverage]\nenabled = false\n\n\
         [zenoh]\nmode = \"router\"\nlisten = [{zenoh:?}]\n{connect}\n\
         [cluster]\nhost = {host:?}\nhosts = [\"h1\", \"h2\"]\nlease_ttl_ms = 3000\n\n\
         [cluster.nats]\nservers = {servers:?}\n",
        store = dir.join("mapper.redb"),
    )
}

fn summary_nodes(http: &str) -> Option<u64> {
    get_json(http, "/api/v1/fleets/park/summary")?["nodes"].as_u64()
}

/// The servers, h1 owning the site, h2 beside it, h2's Zenoh endpoint, the robots' folder.
struct TwoHosts {
    _servers: nats::Cluster,
    /// `None` once killed.
    h1: Option<MapperProcess>,
    h2: MapperProcess,
    z2: String,
    dir: std::path::PathBuf,
}

impl TwoHosts {
    fn start(name: &str) -> TwoHosts {
        Self::start_with(name, None)
    }

    /// With h1 inside `h1_net` when given: its routes to NATS can then be cut alone.
    fn start_with(name: &str, h1_net: Option<&Netns>) -> TwoHosts {
        let dir = temp_dir(name);
        let servers = nats::Cluster::start(name, None);
        let (h1_dir, h2_dir) = (dir.join("h1"), dir.join("h2"));
        std::fs::create_dir_all(&h1_dir).expect("h1 dir");
        std::fs::create_dir_all(&h2_dir).expect("h2 dir");
        let (z1, z2) = (
            format!("tcp/127.0.0.1:{}", free_port()),
            format!("tcp/127.0.0.1:{}", free_port()),
        );
        // h1 alone first: it owns the site.
        let ports = servers.ports();
        let (h1, z1) = match h1_net {
            None => {
                let config = host_config(&h1_dir, "h1", (&z1, None), ("127.0.0.1", ports));
                (
                    MapperProcess::start_config(&h1_dir, z1.clone(), &config),
                    z1,
                )
            }
            Some(net) => {
                // Listening inside its namespace, reached at the namespace's address.
                let (http_port, zenoh_port) = (free_port(), free_port());
                let listen = format!("tcp/0.0.0.0:{zenoh_port}");
                let config = h1_dir.join("mapper.toml");
                let toml = host_config(&h1_dir, "h1", (&listen, None), (&net.host_ip, ports));
                std::fs::write(
                    &config,
                    format!("http_listen = \"0.0.0.0:{http_port}\"\n{toml}"),
                )
                .expect("h1's config");
                let http = format!("{}:{http_port}", net.ns_ip);
                let z1 = format!("tcp/{}:{zenoh_port}", net.ns_ip);
                (
                    MapperProcess::spawn_in(Some(net), http, z1.clone(), config),
                    z1,
                )
            }
        };
        wait_for(Duration::from_secs(60), || summary_nodes(&h1.http))
            .expect("h1 takes the site over");
        let h2 = MapperProcess::start_config(
            &h2_dir,
            z2.clone(),
            &host_config(&h2_dir, "h2", (&z2, Some(&z1)), ("127.0.0.1", ports)),
        );
        assert!(
            summary_nodes(&h2.http).is_none(),
            "h2 must not serve a site h1 owns"
        );
        TwoHosts {
            _servers: servers,
            h1: Some(h1),
            h2,
            z2,
            dir,
        }
    }

    /// The robots, on h2's router (h1's acks reach them through the mesh), once each has
    /// nodes in h1's map; those nodes.
    fn h1_http(&self) -> &str {
        &self.h1.as_ref().expect("h1 runs").http
    }

    fn robots_on_h1(&self) -> (Vec<std::process::Child>, Vec<Vec<u64>>) {
        self.robots_on_h1_via(&[&self.z2])
    }

    /// The robots connecting to `routers`, in turn.
    fn robots_on_h1_via(&self, routers: &[&str]) -> (Vec<std::process::Child>, Vec<Vec<u64>>) {
        let source = "[source.sim]\nduration_s = 60.0\n";
        let edges: Vec<_> = (0..ROBOTS)
            .map(|r| {
                let source = format!("{source}loop_index = {r}\n");
                edge_command_to(&self.dir, r, routers, 4.0, &source)
                    .spawn()
                    .expect("levelmap edge starts")
            })
            .collect();
        let before = wait_for(Duration::from_secs(90), || {
            let seqs: Vec<Vec<u64>> = (0..ROBOTS)
                .map(|r| node_seqs(self.h1_http(), "park", &format!("robot{r}")))
                .collect();
            seqs.iter().all(|s| s.len() >= 3).then_some(seqs)
        })
        .expect("both robots' nodes reach h1's map");
        (edges, before)
    }

    /// Waits for h2 to serve the site; how long after `since`.
    fn h2_takes_over(&self, since: Instant) -> Duration {
        wait_for(Duration::from_secs(60), || {
            let n = summary_nodes(&self.h2.http)?;
            (n > 0).then_some(since.elapsed())
        })
        .expect("h2 takes the site over")
    }

    /// Every node each robot made is in h2's map once, in order.
    fn every_node_once_on_h2(&self, edges: Vec<std::process::Child>) {
        for (r, edge) in edges.into_iter().enumerate() {
            let report = edge_report(edge, Duration::from_secs(180));
            let made = report["nodes"].as_u64().expect("nodes");
            assert_eq!(report["outbox_pending"], 0, "robot{r}: {report}");
            let seqs = node_seqs(&self.h2.http, "park", &format!("robot{r}"));
            assert_eq!(
                seqs,
                (0..made).collect::<Vec<_>>(),
                "robot{r}: every node made, once, in order"
            );
        }
    }
}

impl Drop for TwoHosts {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.dir).ok();
    }
}

#[test]
fn a_host_killed_under_load_loses_no_acked_node_and_its_site_moves() {
    let mut hosts = TwoHosts::start("cluster-host-kill");
    let (edges, before) = hosts.robots_on_h1();
    let killed = Instant::now();
    hosts.h1.take().expect("h1 runs").kill();
    let taken = hosts.h2_takes_over(killed);
    eprintln!(
        "kill: site park served by h2 {:.1} s after h1's kill",
        taken.as_secs_f64()
    );
    assert_restored(&hosts.h2.http, &before);
    hosts.every_node_once_on_h2(edges);
    let metrics = http_get(&hosts.h2.http, "/metrics").expect("metrics").1;
    assert_eq!(metric(&metrics, "levelmap_sites_adopted_total"), 1);
    assert_eq!(metric(&metrics, "levelmap_sites_dropped_total"), 0);
    assert_eq!(metric(&metrics, "levelmap_sites_owned"), 1);
    assert_eq!(metric(&metrics, "levelmap_site_takeover_seconds_count"), 1);
    let appends = metric(&metrics, "levelmap_log_append_seconds_count");
    let acked = metric(&metrics, "levelmap_node_ack_seconds_count");
    assert!(
        appends > 0 && acked > 0,
        "appends {appends}, acked nodes {acked}"
    );
}

#[test]
fn robots_on_the_router_of_a_killed_host_move_to_another_and_lose_nothing() {
    let mut hosts = TwoHosts::start("cluster-router-kill");
    let z1 = hosts.h1.as_ref().expect("h1 runs").zenoh.clone();
    // The robots list both routers, h1's first: they connect to it, the owner's.
    let (edges, before) = hosts.robots_on_h1_via(&[&z1, &hosts.z2]);
    let port = z1.rsplit(':').next().expect("a port");
    let links = common::netns::run(
        "ss",
        &[
            "-Htn",
            "state",
            "established",
            "dport",
            "=",
            &format!(":{port}"),
        ],
    );
    // h2's link to h1 and each robot's.
    assert!(
        links.lines().count() > ROBOTS,
        "the robots must be on h1's router: connections to it\n{links}"
    );
    let killed = Instant::now();
    hosts.h1.take().expect("h1 runs").kill();
    let taken = hosts.h2_takes_over(killed);
    eprintln!(
        "router: site park served by h2 {:.1} s after the kill of h1 and its router",
        taken.as_secs_f64()
    );
    assert_restored(&hosts.h2.http, &before);
    hosts.every_node_once_on_h2(edges);
}

/// `kill -SIG pid`.
fn signal(sig: &str, pid: u32) {
    let ok = std::process::Command::new("kill")
        .args([format!("-{sig}"), pid.to_string()])
        .status()
        .expect("kill runs")
        .success();
    assert!(ok, "kill -{sig} {pid}");
}

#[test]
fn a_host_frozen_past_its_lease_drops_its_site_on_waking_and_loses_nothing() {
    let hosts = TwoHosts::start("cluster-host-freeze");
    let (edges, before) = hosts.robots_on_h1();
    let pid = hosts.h1.as_ref().expect("h1 runs").pid();
    let frozen = Instant::now();
    signal("STOP", pid);
    let taken = hosts.h2_takes_over(frozen);
    eprintln!(
        "freeze: site park served by h2 {:.1} s after h1 froze",
        taken.as_secs_f64()
    );
    assert_restored(&hosts.h2.http, &before);
    // h2 maps the robots' nodes a while, then h1 wakes with its old lease and its queue.
    std::thread::sleep(Duration::from_secs(5));
    signal("CONT", pid);
    let dropped = wait_for(Duration::from_secs(30), || {
        let metrics = http_get(hosts.h1_http(), "/metrics")?.1;
        (metric(&metrics, "levelmap_sites_dropped_total") == 1).then_some(metrics)
    })
    .expect("h1 drops the site on waking");
    eprintln!(
        "freeze: h1's appends fenced after waking: {}",
        metric(&dropped, "levelmap_log_appends_fenced_total")
    );
    assert!(
        summary_nodes(hosts.h1_http()).is_none(),
        "h1 no longer serves the site"
    );
    hosts.every_node_once_on_h2(edges);
}

#[test]
fn a_host_cut_from_nats_stops_acking_within_its_lease_and_its_site_moves() {
    let net = Netns::create("cluster");
    let hosts = TwoHosts::start_with("cluster-host-cut", Some(&net));
    let (edges, before) = hosts.robots_on_h1();
    let acks = |http: &str| {
        metric(
            &http_get(http, "/metrics").expect("metrics").1,
            "levelmap_acks_sent_total",
        )
    };
    // h1 loses NATS only: its Zenoh link to h2 (and so to the robots) stays up.
    let ports: Vec<String> = hosts._servers.ports().iter().map(u16::to_string).collect();
    let ports = ports.join(",");
    let cut = [
        ["OUTPUT", "-d", net.host_ip.as_str(), "--dports"],
        ["INPUT", "-s", net.host_ip.as_str(), "--sports"],
    ];
    let acks_at_cut = acks(hosts.h1_http());
    let cut_at = Instant::now();
    for [chain, flag, address, ports_match] in cut {
        net.iptables(&[
            "-A",
            chain,
            "-p",
            "tcp",
            flag,
            address,
            "-m",
            "multiport",
            ports_match,
            &ports,
            "-j",
            "DROP",
        ]);
    }
    let dropped = wait_for(Duration::from_secs(20), || {
        let text = http_get(hosts.h1_http(), "/metrics")?.1;
        (metric(&text, "levelmap_sites_dropped_total") == 1).then_some(cut_at.elapsed())
    })
    .expect("h1 drops the site once cut from NATS");
    let taken = hosts.h2_takes_over(cut_at);
    let acks_at_takeover = acks(hosts.h1_http());
    std::thread::sleep(Duration::from_secs(5));
    let acks_later = acks(hosts.h1_http());
    eprintln!(
        "cut: h1 dropped the site {:.1} s after the cut, h2 served it {:.1} s after; h1's acks: \
         {acks_at_cut} at the cut, {acks_at_takeover} when h2 took over, {acks_later} 5 s later",
        dropped.as_secs_f64(),
        taken.as_secs_f64()
    );
    // Never two owners acking: none from h1 once h2 has the site.
    assert_eq!(
        acks_at_takeover, acks_later,
        "h1 acked after h2 took the site"
    );
    // Its appends cannot reach NATS, and time out with the lease: dropped within two.
    assert!(
        dropped < Duration::from_secs(6),
        "h1 must drop the site within two 3 s leases, took {dropped:?}"
    );
    assert_restored(&hosts.h2.http, &before);
    // The cut heals: h1 appends nothing more (h2 holds the lease) and every node is on h2.
    for [chain, flag, address, ports_match] in cut {
        net.iptables(&[
            "-D",
            chain,
            "-p",
            "tcp",
            flag,
            address,
            "-m",
            "multiport",
            ports_match,
            &ports,
            "-j",
            "DROP",
        ]);
    }
    hosts.every_node_once_on_h2(edges);
    assert!(
        summary_nodes(hosts.h1_http()).is_none(),
        "h1 does not serve the site"
    );
    let fenced = metric(
        &http_get(hosts.h1_http(), "/metrics").expect("metrics").1,
        "levelmap_log_appends_fenced_total",
    );
    eprintln!("cut: h1's appends fenced after the cut healed: {fenced}");
}
