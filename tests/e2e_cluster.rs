//! Cluster mode drills: two mapper hosts (h1, h2) on a three-node NATS JetStream cluster,
//! their Zenoh routers meshed, two robots on h2's router; h1 owns the site (it is first in
//! the site's order).
//! - h1 killed (SIGKILL) while the robots publish: h2 claims the site's lease once it
//!   lapses, reads the site's log into its own store and maps on, its map restored from
//!   the snapshot h1 shared in the object store and the nodes after it;
//! - the robots on h1's router when h1 is killed: they move to h2's;
//! - h1 frozen (SIGSTOP) past its lease, then let go: h2 takes the site; h1, awake, finds
//!   its lease lost or its append fenced and drops the site; h2 hands it back once h1 has
//!   been alive again for the hand-back time;
//! - h1 cut from NATS by iptables (h1 in its own network namespace): it stops acking within
//!   its lease and h2 takes the site; the cut healed, the site goes back to h1 the same way;
//! - the NATS server leading the site's log killed (SIGKILL): the site maps on once a new
//!   leader is elected;
//! - a rolling restart: h1 stopped and started again (the site moves to h2), then h2 (it
//!   moves back);
//! - a gateway in front: it answers for the owner, 503 while the site has none, then for
//!   h2; killed, another answers at once.
//!
//! In every one, every node acked before the fault is in the map afterwards, and every node
//! the robots made reaches it exactly once. Checked through HTTP only.

mod common;

use common::netns::Netns;
#[path = "../services/sitelog/tests/common/servers.rs"]
mod nats;

use common::*;
use std::path::Path;
use std::time::{Duration, Instant};

const ROBOTS: usize = 2;
/// The hosts' write token.
const TOKEN: &str = "s3cret";

/// A mapper host's config: site `park`, hosts h1 and h2, its Zenoh listening and connecting,
/// the NATS servers at address `nats` on `ports`; a snapshot every 5 nodes, so that every
/// drill's takeovers restore from shared snapshots.
fn host_config(
    dir: &Path,
    host: &str,
    (zenoh, connect): (&str, Option<&str>),
    (nats, ports): (&str, &[u16]),
) -> String {
    let servers: Vec<String> = ports.iter().map(|p| format!("nats://{nats}:{p}")).collect();
    let connect = connect.map_or(String::new(), |c| format!("connect = [{c:?}]\n"));
    format!(
        "store_path = {store:?}\nfleets = [\"park\"]\ntoken = {TOKEN:?}\n\
         [store]\nsnapshot_every_nodes = 5\n\n\
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
    servers: nats::Cluster,
    /// `None` once killed.
    h1: Option<MapperProcess>,
    /// `None` while restarted.
    h2: Option<MapperProcess>,
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
            servers,
            h1: Some(h1),
            h2: Some(h2),
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
        self.robots_on_h1_via(&[&self.z2], 60.0)
    }

    /// The robots connecting to `routers`, in turn, driving `duration_s` (at 4× speed).
    fn robots_on_h1_via(
        &self,
        routers: &[&str],
        duration_s: f64,
    ) -> (Vec<std::process::Child>, Vec<Vec<u64>>) {
        self.robots_on_h1_with(routers, duration_s, "")
    }

    /// [`TwoHosts::robots_on_h1_via`], with `extra` in the robots' configs.
    fn robots_on_h1_with(
        &self,
        routers: &[&str],
        duration_s: f64,
        extra: &str,
    ) -> (Vec<std::process::Child>, Vec<Vec<u64>>) {
        let source = format!("[source.sim]\nduration_s = {duration_s:.1}\n");
        let edges: Vec<_> = (0..ROBOTS)
            .map(|r| {
                let source = format!("{source}loop_index = {r}\n{extra}");
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

    fn h2(&self) -> &MapperProcess {
        self.h2.as_ref().expect("h2 runs")
    }

    /// The host serving the site (its HTTP address) and how many nodes its map holds.
    fn serving(&self) -> Option<(String, u64)> {
        [&self.h1, &self.h2]
            .into_iter()
            .flatten()
            .find_map(|h| Some((h.http.clone(), summary_nodes(&h.http)?)))
    }

    /// Waits for the site's map to hold more than `nodes`, on whichever host serves it; how
    /// long after `since`.
    fn grows_past(&self, nodes: u64, since: Instant) -> Duration {
        wait_for(Duration::from_secs(60), || {
            let (_, now) = self.serving()?;
            (now > nodes).then(|| since.elapsed())
        })
        .expect("the site maps again within 60 s")
    }

    /// Watches the site's map for `window` from `since`: the longest time it did not grow
    /// (the robots publishing all along), on whichever host served it.
    fn longest_pause(&self, since: Instant, window: Duration) -> Duration {
        let (mut last_growth, mut longest) = (since, Duration::ZERO);
        let mut nodes = self.serving().map_or(0, |(_, n)| n);
        while since.elapsed() < window {
            if let Some((_, now)) = self.serving()
                && now > nodes
            {
                nodes = now;
                longest = longest.max(last_growth.elapsed());
                last_growth = Instant::now();
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        longest.max(last_growth.elapsed())
    }

    /// Waits for h2 to serve the site; how long after `since`.
    fn h2_takes_over(&self, since: Instant) -> Duration {
        wait_for(Duration::from_secs(60), || {
            let n = summary_nodes(&self.h2().http)?;
            (n > 0).then_some(since.elapsed())
        })
        .expect("h2 takes the site over")
    }

    /// Every node each robot made is in h2's map once, in order.
    fn every_node_once_on_h2(&self, edges: Vec<std::process::Child>) {
        self.every_node_once(edges, || self.h2().http.clone());
    }

    /// h1, back after a fault, gets the site again from h2 once it has been alive for the
    /// hand-back time (it is first in the site's order); every node made is there once.
    fn every_node_once_back_home_on_h1(&self, edges: Vec<std::process::Child>) {
        self.every_node_once(edges, || {
            wait_for(Duration::from_secs(60), || summary_nodes(self.h1_http()))
                .expect("h2 hands the site back to h1, first in its order");
            self.h1_http().to_owned()
        });
        let metrics = http_get(&self.h2().http, "/metrics").expect("metrics").1;
        assert_eq!(metric(&metrics, "levelmap_sites_handed_back_total"), 1);
    }

    /// Every node each robot made is in the map of the host `serving` names once the robots
    /// are done, once, in order.
    fn every_node_once(&self, edges: Vec<std::process::Child>, serving: impl Fn() -> String) {
        let reports: Vec<_> = edges
            .into_iter()
            .map(|edge| edge_report(edge, Duration::from_secs(180)))
            .collect();
        let http = serving();
        for (r, report) in reports.into_iter().enumerate() {
            let made = report["nodes"].as_u64().expect("nodes");
            assert_eq!(report["outbox_pending"], 0, "robot{r}: {report}");
            let seqs = node_seqs(&http, "park", &format!("robot{r}"));
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
    wait_for(Duration::from_secs(60), || {
        let metrics = http_get(hosts.h1_http(), "/metrics")?.1;
        (metric(&metrics, "levelmap_snapshots_shared_total") > 0).then_some(())
    })
    .expect("h1 shares a snapshot of the site");
    // The robots publish on h2's router, but only h1, the owner, subscribes to the site.
    let h2_metrics = http_get(&hosts.h2().http, "/metrics").expect("metrics").1;
    let not_owner = r#"levelmap_rejected_total{topic="node",reason="not_owner"}"#;
    assert_eq!(
        metric(&h2_metrics, not_owner),
        0,
        "h2 was sent nodes of h1's site"
    );
    let killed = Instant::now();
    hosts.h1.take().expect("h1 runs").kill();
    let taken = hosts.h2_takes_over(killed);
    eprintln!(
        "kill: site park served by h2 {:.1} s after h1's kill",
        taken.as_secs_f64()
    );
    assert_restored(&hosts.h2().http, &before);
    // h2 restored the map from h1's shared snapshot, not by replaying every node.
    let log = std::fs::read_to_string(hosts.dir.join("h2/mapper.log")).expect("h2's log");
    let restored = log
        .lines()
        .map(without_colours)
        .find(|l| l.contains("restored in"))
        .expect("h2 logs its restore");
    let covered: u64 = restored
        .split_whitespace()
        .find_map(|w| w.strip_prefix("snapshot_nodes="))
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("snapshot_nodes in {restored:?}"));
    eprintln!("kill: h2's restore: {restored}");
    assert!(covered > 0, "restored from a shared snapshot: {restored}");
    hosts.every_node_once_on_h2(edges);
    let metrics = http_get(&hosts.h2().http, "/metrics").expect("metrics").1;
    assert_eq!(metric(&metrics, "levelmap_sites_adopted_total"), 1);
    assert_eq!(metric(&metrics, "levelmap_sites_dropped_total"), 0);
    assert_eq!(metric(&metrics, "levelmap_sites_owned"), 1);
    assert_eq!(metric(&metrics, "levelmap_site_takeover_seconds_count"), 1);
    // h2, next in the site's order, followed its log: the takeover read only a tail.
    let followed = metric(&metrics, "levelmap_log_records_followed_total");
    let tail = metric(&metrics, "levelmap_log_records_taken_over_total");
    eprintln!(
        "kill: h2 followed {followed} records of the log as standby; its takeover read {tail}"
    );
    assert!(followed > 0, "h2, the site's standby, follows its log");
    assert!(metric(&metrics, "levelmap_snapshots_taken_in_total") > 0);
    let appends = metric(&metrics, "levelmap_log_append_seconds_count");
    let acked = metric(&metrics, "levelmap_node_ack_seconds_count");
    assert!(
        appends > 0 && acked > 0,
        "appends {appends}, acked nodes {acked}"
    );
}

/// Map versions and robots' modes are records of the site's log: made on h1, they are on
/// h2 after h1's kill as h1 left them, and h2 goes on changing them; a version's number is
/// never given twice, even across hosts. The nodes' clouds, kept apart, are there too.
#[test]
fn versions_modes_and_clouds_move_with_their_site() {
    let mut hosts = TwoHosts::start("cluster-versions");
    // Driving 30 s, with clouds: robot1 still publishes once h2 has taken the site over.
    let z2 = hosts.z2.clone();
    let (edges, _) = hosts.robots_on_h1_with(&[&z2], 120.0, "[cloud]\nkeep = true\n");
    let (h1, h2) = (hosts.h1_http().to_owned(), hosts.h2().http.clone());
    let versions = "/api/v1/fleets/park/versions";
    let modes = "/api/v1/fleets/park/modes";
    let json = |body: &[u8]| serde_json::from_slice::<serde_json::Value>(body).expect("JSON");
    let made = |http: &str| {
        let (status, body, _) = call(http, "POST", versions, TOKEN, b"");
        assert_eq!(status, 201, "{}", String::from_utf8_lossy(&body));
        json(&body)["version"].as_u64().expect("a number")
    };
    assert_eq!(made(&h1), 1);
    assert_eq!(made(&h1), 2);
    let (status, ..) = call(&h1, "DELETE", &format!("{versions}/2"), TOKEN, b"");
    assert_eq!(status, 204);
    let (_, file, _) = call(&h1, "GET", &format!("{versions}/1/file"), TOKEN, b"");
    let localize = br#"{"mode": "localize", "version": 1, "robots": ["robot1"]}"#;
    let (status, body, _) = call(&h1, "PUT", modes, TOKEN, localize);
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    // h2 holds no lease: it changes nothing (the site's owner alone appends to its log).
    let map_all = br#"{"mode": "map"}"#;
    let (status, ..) = call(&h2, "PUT", modes, TOKEN, map_all);
    assert_ne!(
        status, 200,
        "a change of modes on a host that does not own the site"
    );

    // Node 1's cloud, once h1 has shared it.
    let cloud = "/api/v1/fleets/park/nodes/1/cloud";
    wait_for(Duration::from_secs(30), || {
        let metrics = http_get(&h1, "/metrics")?.1;
        (metric(&metrics, "levelmap_clouds_shared_total") > 1).then_some(())
    })
    .expect("h1 shares its nodes' clouds");
    let (status, cloud_on_h1, _) = call(&h1, "GET", cloud, TOKEN, b"");
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&cloud_on_h1));

    let killed = Instant::now();
    hosts.h1.take().expect("h1 runs").kill();
    let taken = hosts.h2_takes_over(killed);
    eprintln!(
        "versions: h2 serves the site {:.1} s after h1's kill",
        taken.as_secs_f64()
    );
    let (status, cloud_on_h2, _) = call(&h2, "GET", cloud, TOKEN, b"");
    assert_eq!(status, 200, "h2 serves node 1's cloud, mapped on h1");
    assert!(cloud_on_h2 == cloud_on_h1, "node 1's cloud on h2 is h1's");
    let (_, body, _) = call(&h2, "GET", versions, TOKEN, b"");
    let listed: Vec<u64> = json(&body)["versions"]
        .as_array()
        .expect("versions")
        .iter()
        .map(|v| v["version"].as_u64().expect("a number"))
        .collect();
    assert_eq!(listed, [1], "h2 keeps version 1, and not the deleted 2");
    let (status, moved, _) = call(&h2, "GET", &format!("{versions}/1/file"), TOKEN, b"");
    assert_eq!(status, 200);
    assert!(
        moved == file,
        "version 1's file on h2 is h1's, byte for byte"
    );
    let (_, body, _) = call(&h2, "GET", modes, TOKEN, b"");
    let now = json(&body);
    assert_eq!(
        now["modes"]["robots"]["robot1"],
        serde_json::json!({"mode": "localize", "version": 1}),
        "{now}"
    );
    // h2's worker was handed the modes with the site: it localizes robot1's nodes.
    let localized = wait_for(Duration::from_secs(30), || {
        let answer = http_get(&h2, "/api/v1/fleets/park/robots/robot1/localization")?;
        (answer.0 == 200).then_some(answer.1)
    });
    assert!(localized.is_some(), "h2 localizes robot1 on version 1");
    // h2, the owner now, changes them on: robot1 in use of 1 until it maps again.
    let (status, ..) = call(&h2, "DELETE", &format!("{versions}/1"), TOKEN, b"");
    assert_eq!(status, 409, "version 1 is in use by robot1");
    let (status, ..) = call(&h2, "PUT", modes, TOKEN, map_all);
    assert_eq!(status, 200);
    let (status, ..) = call(&h2, "DELETE", &format!("{versions}/1"), TOKEN, b"");
    assert_eq!(status, 204);
    assert_eq!(made(&h2), 3, "numbers 1 and 2 were given on h1");
    // Every robot's every node acked, mapped or localized.
    for (r, edge) in edges.into_iter().enumerate() {
        let report = edge_report(edge, Duration::from_secs(180));
        assert_eq!(report["outbox_pending"], 0, "robot{r}: {report}");
    }
}

#[test]
fn robots_on_the_router_of_a_killed_host_move_to_another_and_lose_nothing() {
    let mut hosts = TwoHosts::start("cluster-router-kill");
    let z1 = hosts.h1.as_ref().expect("h1 runs").zenoh.clone();
    // The robots list both routers, h1's first: they connect to it, the owner's.
    let (edges, before) = hosts.robots_on_h1_via(&[&z1, &hosts.z2], 60.0);
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
    assert_restored(&hosts.h2().http, &before);
    hosts.every_node_once_on_h2(edges);
}

/// The server leading `stream`, as the servers' monitoring (`/jsz`) says.
fn stream_leader(servers: &nats::Cluster, stream: &str) -> Option<String> {
    servers.monitor_ports().iter().find_map(|port| {
        let jsz = get_json(
            &format!("127.0.0.1:{port}"),
            "/jsz?accounts=true&streams=true",
        )?;
        jsz["account_details"]
            .as_array()?
            .iter()
            .flat_map(|a| a["stream_detail"].as_array().into_iter().flatten())
            .find(|s| s["name"] == stream)
            .and_then(|s| s["cluster"]["leader"].as_str().map(str::to_owned))
    })
}

#[test]
fn the_nats_server_leading_the_sites_log_killed_under_load_loses_nothing() {
    nats_leader_killed("cluster-nats-kill", "LEVELMAP_SITE_park");
}

/// The leases bucket's leader lost: no renewal is answered until a new one is elected, which
/// takes longer than the lease (docs/cluster.md).
#[test]
fn the_nats_server_leading_the_leases_killed_under_load_loses_nothing() {
    nats_leader_killed("cluster-nats-leases-kill", "KV_levelmap_site_leases");
}

/// SIGKILLs the NATS server leading `stream` while the robots publish; the site maps again
/// and every node is in its map once.
fn nats_leader_killed(name: &str, stream: &str) {
    let mut hosts = TwoHosts::start(name);
    // On the road through the whole window watched.
    let (edges, _) = hosts.robots_on_h1_via(&[&hosts.z2], 160.0);
    let leader = |stream| {
        wait_for(Duration::from_secs(10), || {
            stream_leader(&hosts.servers, stream)
        })
        .expect("the stream has a leader")
    };
    let (killed_leader, site, leases) = (
        leader(stream),
        leader("LEVELMAP_SITE_park"),
        leader("KV_levelmap_site_leases"),
    );
    let (_, nodes_at_kill) = hosts.serving().expect("a host serves the site");
    let killed = Instant::now();
    hosts.servers.kill(&killed_leader);
    let resumed = hosts.grows_past(nodes_at_kill, killed);
    let pause = hosts.longest_pause(killed, Duration::from_secs(20));
    eprintln!(
        "nats: {killed_leader}, leading {stream}, killed (the site's log led by {site}, the \
         leases by {leases}); the map grew again {:.1} s after; its longest pause in the 20 s \
         after the kill {:.1} s",
        resumed.as_secs_f64(),
        pause.as_secs_f64()
    );
    hosts.every_node_once(edges, || hosts.serving().expect("a host serves the site").0);
    for (name, host) in [("h1", &hosts.h1), ("h2", &hosts.h2)] {
        let config = &host.as_ref().expect("runs").config;
        let log = std::fs::read_to_string(config.with_extension("log")).unwrap_or_default();
        for line in log
            .lines()
            .filter(|l| l.contains("cluster:") || l.contains("site "))
        {
            eprintln!("nats: {name}: {}", without_colours(line));
        }
    }
}

#[test]
fn every_host_restarted_one_at_a_time_loses_nothing() {
    let mut hosts = TwoHosts::start("cluster-rolling");
    let z1 = hosts.h1.as_ref().expect("h1 runs").zenoh.clone();
    let z2 = hosts.z2.clone();
    // Robots long enough on the road for two restarts, on h2's router first, then h1's.
    let (edges, _) = hosts.robots_on_h1_via(&[&z2, &z1], 240.0);
    let mut pauses = Vec::new();
    for host in ["h1", "h2"] {
        let (_, nodes) = hosts.serving().expect("a host serves the site");
        let stopped = Instant::now();
        let slot = if host == "h1" {
            &mut hosts.h1
        } else {
            &mut hosts.h2
        };
        let old = slot.take().expect("runs").stop();
        let pause = hosts.grows_past(nodes, stopped);
        pauses.push(format!("{host} {:.1} s", pause.as_secs_f64()));
        let started = MapperProcess::restart(old);
        assert!(
            summary_nodes(&started.http).is_none(),
            "{host}, started again, must not serve the site the other host took"
        );
        let slot = if host == "h1" {
            &mut hosts.h1
        } else {
            &mut hosts.h2
        };
        *slot = Some(started);
    }
    eprintln!(
        "rolling: the site mapped again after the stop of {}",
        pauses.join(", after the stop of ")
    );
    // h1 serves it again: the site moved there and back.
    hosts.every_node_once(edges, || hosts.h1_http().to_owned());
}

/// A `levelmap gateway` in front of the running hosts.
struct GatewayProcess {
    http: String,
    child: std::process::Child,
}

impl GatewayProcess {
    /// Listing each mapper host's HTTP address: `hosts` (name, address).
    fn start(cluster: &TwoHosts, name: &str, hosts: &[(&str, String)]) -> GatewayProcess {
        let http = format!("127.0.0.1:{}", free_port());
        let servers: Vec<String> = cluster
            .servers
            .ports()
            .iter()
            .map(|p| format!("nats://127.0.0.1:{p}"))
            .collect();
        let hosts: String = hosts
            .iter()
            .map(|(host, address)| format!("{host} = {address:?}\n"))
            .collect();
        let config = cluster.dir.join(format!("{name}.toml"));
        std::fs::write(
            &config,
            format!("http_listen = {http:?}\n[hosts]\n{hosts}[nats]\nservers = {servers:?}\n"),
        )
        .expect("gateway config");
        let log = std::fs::File::create(config.with_extension("log")).expect("gateway log");
        let child = levelmap()
            .args(["gateway", "--config"])
            .arg(&config)
            .stdout(std::process::Stdio::null())
            .stderr(log)
            .spawn()
            .expect("levelmap gateway starts");
        wait_for(Duration::from_secs(30), || http_get(&http, "/healthz")).expect("gateway up");
        GatewayProcess { http, child }
    }
}

impl Drop for GatewayProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn a_gateway_answers_for_the_sites_owner_and_follows_it_to_another_host() {
    let mut hosts = TwoHosts::start("cluster-gateway");
    let addresses = [
        ("h1", hosts.h1_http().to_owned()),
        ("h2", hosts.h2().http.clone()),
    ];
    let gateway = GatewayProcess::start(&hosts, "g1", &addresses);
    let (edges, before) = hosts.robots_on_h1();
    let summary = get_json(&gateway.http, "/api/v1/fleets/park/summary").expect("summary");
    assert!(summary["nodes"].as_u64() > Some(0), "{summary}");
    let list = get_json(&gateway.http, "/api/v1/fleets").expect("fleet list");
    assert_eq!(list["fleets"], serde_json::json!(["park"]), "{list}");
    let status = |path: &str| http_get(&gateway.http, path).map(|(status, _)| status);
    assert_eq!(status("/api/v1/fleets/nowhere/summary"), Some(404));
    assert_eq!(status("/api/v1/openapi.json"), Some(200));
    assert_eq!(status("/metrics"), Some(404), "a gateway keeps no metrics");
    // The event stream, every host's merged: the robots' nodes come on it.
    let mut events = common::sse::Sse::open(&gateway.http, "/api/v1/events");
    let node = wait_for(Duration::from_secs(10), || {
        let event = events.next();
        (event["type"] == "node").then_some(event)
    })
    .expect("a node event through the gateway");
    assert_eq!(node["fleet"], "park", "{node}");
    drop(events);
    // A robot's live feed, a WebSocket, through the gateway to the owner.
    let url = format!(
        "ws://{}/api/v1/fleets/park/robots/robot0/live",
        gateway.http
    );
    let (mut socket, _) = tungstenite::connect(url).expect("the WebSocket opens");
    let sample = loop {
        match socket.read().expect("a message") {
            tungstenite::Message::Text(text) => break text,
            tungstenite::Message::Ping(_) | tungstenite::Message::Pong(_) => {}
            other => panic!("{other:?}"),
        }
    };
    let sample: serde_json::Value = serde_json::from_str(&sample).expect("JSON");
    assert!(sample.is_object(), "{sample}");
    socket.close(None).ok();
    // h1 killed: 503 with Retry-After while its lease runs out, then h2's answers.
    let killed = Instant::now();
    hosts.h1.take().expect("h1 runs").kill();
    let mut unavailable = 0;
    let served = wait_for(Duration::from_secs(60), || {
        let answer = http_call(&gateway.http, "GET", "/api/v1/fleets/park/summary", &[])?;
        if answer.status == 503 {
            assert!(answer.header("retry-after").is_some(), "{}", answer.body);
            unavailable += 1;
        }
        (answer.status == 200).then(|| killed.elapsed())
    })
    .expect("the gateway answers for the site again");
    eprintln!(
        "gateway: the site answered 200 through the gateway {:.1} s after h1's kill ({unavailable} \
         answers 503 with Retry-After before)",
        served.as_secs_f64()
    );
    assert!(unavailable > 0, "503 while nobody serves the site");
    // The gateway killed and another started: it keeps nothing, and answers at once.
    drop(gateway);
    let gateway = GatewayProcess::start(&hosts, "g2", &addresses);
    assert_restored(&gateway.http, &before);
    hosts.every_node_once_on_h2(edges);
    for r in 0..ROBOTS {
        let robot = format!("robot{r}");
        assert_eq!(
            node_seqs(&gateway.http, "park", &robot),
            node_seqs(&hosts.h2().http, "park", &robot),
            "{robot}: the gateway answers as the owner"
        );
    }
}

/// `line` without its ANSI colour codes (`ESC [ … m`).
fn without_colours(line: &str) -> String {
    let mut out = String::with_capacity(line.len());
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            chars.by_ref().find(|&c| c == 'm');
        } else {
            out.push(c);
        }
    }
    out
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
    assert_restored(&hosts.h2().http, &before);
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
    hosts.every_node_once_back_home_on_h1(edges);
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
    let ports: Vec<String> = hosts.servers.ports().iter().map(u16::to_string).collect();
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
    assert_restored(&hosts.h2().http, &before);
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
    assert!(
        summary_nodes(hosts.h1_http()).is_none(),
        "h1 does not serve the site on its own once the cut heals"
    );
    hosts.every_node_once_back_home_on_h1(edges);
    let fenced = metric(
        &http_get(hosts.h1_http(), "/metrics").expect("metrics").1,
        "levelmap_log_appends_fenced_total",
    );
    eprintln!("cut: h1's appends fenced after the cut healed: {fenced}");
}
