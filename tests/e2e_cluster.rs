//! Cluster mode drills: five mapper hosts (h1–h5), each in a network namespace of its own on
//! one LAN, the three NATS JetStream servers in the namespaces of three of them, their Zenoh
//! routers meshed, the robots in a namespace of their own, a gateway in another; the test
//! reaches them all over the LAN. The site's rendezvous order over h1–h5 is h4, h1, h5, h2,
//! h3: h4 owns the site, h1 stands by, and the NATS servers run beside h5, h2 and h3 (so the
//! owner's and the standby's kills lose no NATS server; the drills of NATS servers kill them
//! alone).
//! - the owner killed (SIGKILL) while the robots publish: the standby claims the site's lease
//!   once it lapses, reads the site's log into its own store and maps on, its map restored
//!   from the snapshot the owner shared in the object store and the nodes after it;
//! - the robots on the owner's router when it is killed: they move to the standby's;
//! - the owner frozen (SIGSTOP) past its lease, then let go: the standby takes the site; the
//!   owner, awake, finds its lease lost or its append fenced and drops the site; the standby
//!   hands it back once the owner has been alive again for the hand-back time;
//! - the owner cut from NATS by iptables in its namespace: it stops acking within its lease
//!   and the standby takes the site; the cut healed, the site goes back the same way;
//! - the NATS server leading the site's log (or the leases) killed (SIGKILL): the site maps on
//!   once a new leader is elected, on the same owner;
//! - every process of the owner's host killed, a NATS server among them: the standby, and no
//!   other host, takes the site;
//! - a rolling restart: every host stopped and started again, one at a time, h1 to h5 (the
//!   site moves to the standby while the owner is down, and back);
//! - a gateway in front: it answers for the owner, 503 while the site has none, then for
//!   the standby; killed, another answers at once.
//!
//! In every one, every node acked before the fault is in the map afterwards, and every node
//! the robots made reaches it exactly once. Checked through HTTP only. The machines and the
//! drills' ways of looking at them are in `e2e_cluster/hosts.rs`.

mod common;

#[path = "e2e_cluster/hosts.rs"]
mod hosts;
#[path = "../services/sitelog/tests/common/servers.rs"]
mod nats;

use common::netns::Namespace;
use common::*;
use hosts::*;
use std::time::{Duration, Instant};

#[test]
fn a_host_killed_under_load_loses_no_acked_node_and_its_site_moves() {
    let mut hosts = Hosts::start("cluster-host-kill");
    let (edges, before) = hosts.robots_on_owner();
    wait_for(Duration::from_secs(60), || {
        let metrics = http_get(&hosts.owner().http, "/metrics")?.1;
        (metric(&metrics, "levelmap_snapshots_shared_total") > 0).then_some(())
    })
    .expect("the owner shares a snapshot of the site");
    // The robots publish on the standby's router, but only the owner subscribes to the site.
    let standby_metrics = http_get(&hosts.standby().http, "/metrics")
        .expect("metrics")
        .1;
    let not_owner = r#"levelmap_rejected_total{topic="node",reason="not_owner"}"#;
    assert_eq!(
        metric(&standby_metrics, not_owner),
        0,
        "the standby was sent nodes of the owner's site"
    );
    let killed = Instant::now();
    hosts.kill_owner();
    let taken = hosts.standby_takes_over(killed);
    eprintln!(
        "kill: site park served by the standby {:.1} s after the owner's kill",
        taken.as_secs_f64()
    );
    assert_restored(&hosts.standby().http, &before);
    // The standby restored the map from the owner's shared snapshot, not by replaying every
    // node.
    let log = std::fs::read_to_string(hosts.standby().config.with_extension("log"))
        .expect("the standby's log");
    let restored = log
        .lines()
        .map(without_colours)
        .find(|l| l.contains("restored in"))
        .expect("the standby logs its restore");
    let covered: u64 = restored
        .split_whitespace()
        .find_map(|w| w.strip_prefix("snapshot_nodes="))
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("snapshot_nodes in {restored:?}"));
    eprintln!("kill: the standby's restore: {restored}");
    assert!(covered > 0, "restored from a shared snapshot: {restored}");
    hosts.every_node_once_on_standby(edges);
    let metrics = http_get(&hosts.standby().http, "/metrics")
        .expect("metrics")
        .1;
    assert_eq!(metric(&metrics, "levelmap_sites_adopted_total"), 1);
    assert_eq!(metric(&metrics, "levelmap_sites_dropped_total"), 0);
    assert_eq!(metric(&metrics, "levelmap_sites_owned"), 1);
    // The owner's process gone, its Zenoh token went with its links: the standby took the
    // lease over then, not on its lapse.
    assert_eq!(metric(&metrics, "levelmap_leases_taken_from_gone_total"), 1);
    assert_eq!(metric(&metrics, "levelmap_site_takeover_seconds_count"), 1);
    // The standby, next in the site's order, followed its log: the takeover read only a tail.
    let followed = metric(&metrics, "levelmap_log_records_followed_total");
    let tail = metric(&metrics, "levelmap_log_records_taken_over_total");
    eprintln!("kill: the standby followed {followed} records of the log; its takeover read {tail}");
    assert!(followed > 0, "the site's standby follows its log");
    assert!(metric(&metrics, "levelmap_snapshots_taken_in_total") > 0);
    let appends = metric(&metrics, "levelmap_log_append_seconds_count");
    let acked = metric(&metrics, "levelmap_node_ack_seconds_count");
    assert!(
        appends > 0 && acked > 0,
        "appends {appends}, acked nodes {acked}"
    );
}

/// Every process of the owner's host killed at once: its mapper and the NATS server beside
/// it (leading the site's log, the leases, both or neither: whatever the election made it).
#[test]
fn a_host_killed_with_its_nats_server_under_load_loses_nothing() {
    let mut hosts = Hosts::start_with("cluster-host-and-nats-kill", true);
    let (edges, before) = hosts.robots_on_owner();
    let server = hosts
        .nats_hosts
        .iter()
        .position(|&h| h == hosts.owner)
        .map(|i| format!("n{}", i + 1))
        .expect("a server beside the owner");
    let led: Vec<&str> = ["LEVELMAP_SITE_park", "KV_levelmap_site_leases"]
        .into_iter()
        .filter(|stream| stream_leader(&hosts.servers, stream).as_deref() == Some(&server))
        .collect();
    let (_, nodes_at_kill) = hosts.serving().expect("the owner serves the site");
    let killed = Instant::now();
    hosts.kill_owner();
    hosts.servers.kill(&server);
    let taken = hosts.standby_takes_over(killed);
    let grew = hosts.grows_past(nodes_at_kill, killed);
    eprintln!(
        "host and nats: the owner and {server} (leading {led:?}) killed; the standby served the \
         site {:.1} s after, its map grew again {:.1} s after",
        taken.as_secs_f64(),
        grew.as_secs_f64()
    );
    assert_restored(&hosts.standby().http, &before);
    hosts.every_node_once_on_standby(edges);
    hosts.print_site_logs("host and nats");
    // The standby and no other: the hosts' ranks held through the leases' election.
    for (h, host) in hosts.hosts.iter().enumerate() {
        let Some(host) = host.as_ref().filter(|_| h != hosts.standby) else {
            continue;
        };
        let metrics = http_get(&host.http, "/metrics").expect("metrics").1;
        assert_eq!(
            metric(&metrics, "levelmap_sites_adopted_total"),
            0,
            "{} took the site, not the standby",
            HOSTS[h]
        );
    }
}

/// Map versions and robots' modes are records of the site's log: made on the owner, they are
/// on the standby after the owner's kill as the owner left them, and the standby goes on
/// changing them; a version's number is never given twice, even across hosts. The nodes'
/// clouds, kept apart, are there too.
#[test]
fn versions_modes_and_clouds_move_with_their_site() {
    let mut hosts = Hosts::start("cluster-versions");
    // Driving 30 s, with clouds: robot1 still publishes once the standby has taken the site over.
    let z2 = hosts.routers[hosts.standby].clone();
    let (edges, _) = hosts.robots_on_owner_with(&[&z2], 120.0, "[cloud]\nkeep = true\n");
    let (owner, standby) = (hosts.owner().http.clone(), hosts.standby().http.clone());
    let versions = "/api/v1/fleets/park/versions";
    let modes = "/api/v1/fleets/park/modes";
    let json = |body: &[u8]| serde_json::from_slice::<serde_json::Value>(body).expect("JSON");
    let made = |http: &str| {
        let (status, body, _) = call(http, "POST", versions, TOKEN, b"");
        assert_eq!(status, 201, "{}", String::from_utf8_lossy(&body));
        json(&body)["version"].as_u64().expect("a number")
    };
    assert_eq!(made(&owner), 1);
    assert_eq!(made(&owner), 2);
    let (status, ..) = call(&owner, "DELETE", &format!("{versions}/2"), TOKEN, b"");
    assert_eq!(status, 204);
    let (_, file, _) = call(&owner, "GET", &format!("{versions}/1/file"), TOKEN, b"");
    let localize = br#"{"mode": "localize", "version": 1, "robots": ["robot1"]}"#;
    let (status, body, _) = call(&owner, "PUT", modes, TOKEN, localize);
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    // The standby holds no lease: it changes nothing (the site's owner alone appends to its log).
    let map_all = br#"{"mode": "map"}"#;
    let (status, ..) = call(&standby, "PUT", modes, TOKEN, map_all);
    assert_ne!(
        status, 200,
        "a change of modes on a host that does not own the site"
    );

    // Node 1's cloud, once the owner has shared it.
    let cloud = "/api/v1/fleets/park/nodes/1/cloud";
    wait_for(Duration::from_secs(30), || {
        let metrics = http_get(&owner, "/metrics")?.1;
        (metric(&metrics, "levelmap_clouds_shared_total") > 1).then_some(())
    })
    .expect("the owner shares its nodes' clouds");
    let (status, cloud_on_owner, _) = call(&owner, "GET", cloud, TOKEN, b"");
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&cloud_on_owner));

    let killed = Instant::now();
    hosts.kill_owner();
    let taken = hosts.standby_takes_over(killed);
    eprintln!(
        "versions: the standby serves the site {:.1} s after the owner's kill",
        taken.as_secs_f64()
    );
    let (status, cloud_on_standby, _) = call(&standby, "GET", cloud, TOKEN, b"");
    assert_eq!(
        status, 200,
        "the standby serves node 1's cloud, mapped on the owner"
    );
    assert!(
        cloud_on_standby == cloud_on_owner,
        "node 1's cloud on the standby is the owner's"
    );
    let (_, body, _) = call(&standby, "GET", versions, TOKEN, b"");
    let listed: Vec<u64> = json(&body)["versions"]
        .as_array()
        .expect("versions")
        .iter()
        .map(|v| v["version"].as_u64().expect("a number"))
        .collect();
    assert_eq!(
        listed,
        [1],
        "the standby keeps version 1, and not the deleted 2"
    );
    let (status, moved, _) = call(&standby, "GET", &format!("{versions}/1/file"), TOKEN, b"");
    assert_eq!(status, 200);
    assert!(
        moved == file,
        "version 1's file on the standby is the owner's, byte for byte"
    );
    let (_, body, _) = call(&standby, "GET", modes, TOKEN, b"");
    let now = json(&body);
    assert_eq!(
        now["modes"]["robots"]["robot1"],
        serde_json::json!({"mode": "localize", "version": 1}),
        "{now}"
    );
    // The standby's worker was handed the modes with the site: it localizes robot1's nodes.
    let localized = wait_for(Duration::from_secs(30), || {
        let answer = http_get(&standby, "/api/v1/fleets/park/robots/robot1/localization")?;
        (answer.0 == 200).then_some(answer.1)
    });
    assert!(
        localized.is_some(),
        "the standby localizes robot1 on version 1"
    );
    // The standby, the owner now, changes them on: robot1 in use of 1 until it maps again.
    let (status, ..) = call(&standby, "DELETE", &format!("{versions}/1"), TOKEN, b"");
    assert_eq!(status, 409, "version 1 is in use by robot1");
    let (status, ..) = call(&standby, "PUT", modes, TOKEN, map_all);
    assert_eq!(status, 200);
    let (status, ..) = call(&standby, "DELETE", &format!("{versions}/1"), TOKEN, b"");
    assert_eq!(status, 204);
    assert_eq!(made(&standby), 3, "numbers 1 and 2 were given on the owner");
    // Every robot's every node acked, mapped or localized.
    for (r, edge) in edges.into_iter().enumerate() {
        let report = edge_report(edge, Duration::from_secs(180));
        assert_eq!(report["outbox_pending"], 0, "robot{r}: {report}");
    }
}

#[test]
fn robots_on_the_router_of_a_killed_host_move_to_another_and_lose_nothing() {
    let mut hosts = Hosts::start("cluster-router-kill");
    let (owner, standby) = (
        hosts.routers[hosts.owner].clone(),
        hosts.routers[hosts.standby].clone(),
    );
    // The robots list both routers, the owner's first: they connect to it.
    let (edges, before) = hosts.robots_on_owner_via(&[&owner, &standby], 60.0);
    let port = owner.rsplit(':').next().expect("a port");
    let links = common::netns::run(
        "ip",
        &[
            "netns",
            "exec",
            &hosts.member("robots").ns,
            "ss",
            "-Htn",
            "state",
            "established",
            "dport",
            "=",
            &format!(":{port}"),
        ],
    );
    assert!(
        links.lines().count() >= ROBOTS,
        "the robots must be on the owner's router: their connections to it\n{links}"
    );
    let killed = Instant::now();
    hosts.kill_owner();
    let taken = hosts.standby_takes_over(killed);
    eprintln!(
        "router: site park served by the standby {:.1} s after the kill of the owner and its \
         router",
        taken.as_secs_f64()
    );
    assert_restored(&hosts.standby().http, &before);
    hosts.every_node_once_on_standby(edges);
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
    let mut hosts = Hosts::start(name);
    // On the road through the whole window watched.
    let standby = hosts.routers[hosts.standby].clone();
    let (edges, _) = hosts.robots_on_owner_via(&[&standby], 160.0);
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
    // The owner shows the site's log's copies on /metrics: three current, then two.
    copies_become(&hosts, 3);
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
    copies_become(&hosts, 2);
    hosts.print_site_logs("nats");
    // The owner's renewals go unanswered through the election, shorter than the lease and
    // its grace: it keeps the site (claiming its lease again if it lapsed).
    let metrics = http_get(&hosts.owner().http, "/metrics")
        .expect("metrics")
        .1;
    eprintln!(
        "nats: the owner claimed its lapsed lease again {} times",
        metric(&metrics, "levelmap_leases_reclaimed_total")
    );
    assert_eq!(
        metric(&metrics, "levelmap_sites_dropped_total"),
        0,
        "the owner kept the site through the election"
    );
}

/// Waits until the owner's `/metrics` shows `want` current copies of the site's log (it reads
/// them every 10 s).
fn copies_become(hosts: &Hosts, want: u64) {
    let copies = r#"levelmap_site_log_copies_current{site="park"}"#;
    wait_for(Duration::from_secs(30), || {
        let metrics = http_get(&hosts.owner().http, "/metrics")?.1;
        (metric(&metrics, copies) == want).then_some(())
    })
    .unwrap_or_else(|| panic!("the owner's {copies} never {want} in 30 s"));
}

#[test]
fn every_host_restarted_one_at_a_time_loses_nothing() {
    let mut hosts = Hosts::start("cluster-rolling");
    // Robots long enough on the road for five restarts and the hand-back, listing every router.
    let routers = hosts.routers.clone();
    let routers: Vec<&str> = routers.iter().map(String::as_str).collect();
    let (edges, _) = hosts.robots_on_owner_via(&routers, 400.0);
    let mut pauses = Vec::new();
    for (h, host) in HOSTS.iter().enumerate() {
        let (_, nodes) = hosts.serving().expect("a host serves the site");
        let stopped = Instant::now();
        let old = hosts.hosts[h].take().expect("runs").stop();
        let pause = hosts.grows_past(nodes, stopped);
        pauses.push(format!("{host} {:.1} s", pause.as_secs_f64()));
        let started = MapperProcess::restart(old);
        assert!(
            summary_nodes(&started.http).is_none(),
            "{host}, started again, must not serve the site another host holds"
        );
        hosts.hosts[h] = Some(started);
    }
    eprintln!(
        "rolling: the site mapped again after the stop of {}",
        pauses.join(", after the stop of ")
    );
    // The owner serves it again: the site moved to the standby and back.
    hosts.every_node_once_back_home(edges);
}

#[test]
fn a_gateway_answers_for_the_sites_owner_and_follows_it_to_another_host() {
    let mut hosts = Hosts::start("cluster-gateway");
    let gateway = GatewayProcess::start(&hosts, "g1");
    let (edges, before) = hosts.robots_on_owner();
    let summary = get_json(&gateway.http, "/api/v1/fleets/park/summary").expect("summary");
    assert!(summary["nodes"].as_u64() > Some(0), "{summary}");
    let list = get_json(&gateway.http, "/api/v1/fleets").expect("fleet list");
    assert_eq!(list["fleets"], serde_json::json!(["park"]), "{list}");
    let status = |path: &str| http_get(&gateway.http, path).map(|(status, _)| status);
    assert_eq!(status("/api/v1/fleets/nowhere/summary"), Some(404));
    assert_eq!(status("/api/v1/openapi.json"), Some(200));
    // The gateway's own metrics: its answers by route and status.
    let answers = |code: &str| {
        let text = http_get(&gateway.http, "/metrics")
            .expect("the gateway's metrics")
            .1;
        let series = format!("levelmap_gateway_answers_total{{route=\"site\",code=\"{code}\"}}");
        metric(&text, &series)
    };
    assert!(answers("200") >= 1, "the summary counted");
    assert_eq!(answers("404"), 1, "the site nowhere counted");
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
    // The owner killed: 503 with Retry-After while its lease runs out, then the standby's
    // answers.
    let killed = Instant::now();
    hosts.kill_owner();
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
        "gateway: the site answered 200 through the gateway {:.1} s after the owner's kill ({unavailable} \
         answers 503 with Retry-After before)",
        served.as_secs_f64()
    );
    assert!(unavailable > 0, "503 while nobody serves the site");
    assert!(
        answers("503") >= unavailable,
        "each 503 counted by the gateway"
    );
    // The gateway killed and another started: it keeps nothing, and answers at once.
    drop(gateway);
    let gateway = GatewayProcess::start(&hosts, "g2");
    assert_restored(&gateway.http, &before);
    hosts.every_node_once_on_standby(edges);
    for r in 0..ROBOTS {
        let robot = format!("robot{r}");
        assert_eq!(
            node_seqs(&gateway.http, "park", &robot),
            node_seqs(&hosts.standby().http, "park", &robot),
            "{robot}: the gateway answers as the owner"
        );
    }
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
    let hosts = Hosts::start("cluster-host-freeze");
    let (edges, before) = hosts.robots_on_owner();
    let pid = hosts.owner().pid();
    let frozen = Instant::now();
    signal("STOP", pid);
    let taken = hosts.standby_takes_over(frozen);
    eprintln!(
        "freeze: site park served by the standby {:.1} s after the owner froze",
        taken.as_secs_f64()
    );
    assert_restored(&hosts.standby().http, &before);
    // A frozen process keeps its links (Zenoh times them out after 10 s): the site moved on
    // the lease's lapse, not as from a process gone.
    let metrics = http_get(&hosts.standby().http, "/metrics")
        .expect("metrics")
        .1;
    assert_eq!(metric(&metrics, "levelmap_leases_taken_from_gone_total"), 0);
    // The standby maps the robots' nodes a while, then the owner wakes with its old lease and
    // its queue.
    std::thread::sleep(Duration::from_secs(5));
    signal("CONT", pid);
    let dropped = wait_for(Duration::from_secs(30), || {
        let metrics = http_get(&hosts.owner().http, "/metrics")?.1;
        (metric(&metrics, "levelmap_sites_dropped_total") == 1).then_some(metrics)
    })
    .expect("the owner drops the site on waking");
    eprintln!(
        "freeze: the owner's appends fenced after waking: {}",
        metric(&dropped, "levelmap_log_appends_fenced_total")
    );
    assert!(
        summary_nodes(&hosts.owner().http).is_none(),
        "the owner no longer serves the site"
    );
    hosts.every_node_once_back_home(edges);
}

#[test]
fn a_host_cut_from_nats_stops_acking_within_its_lease_and_its_site_moves() {
    let hosts = Hosts::start("cluster-host-cut");
    let (edges, before) = hosts.robots_on_owner();
    let net = hosts.member(HOSTS[hosts.owner]);
    let acks = |http: &str| {
        metric(
            &http_get(http, "/metrics").expect("metrics").1,
            "levelmap_acks_sent_total",
        )
    };
    // The owner loses NATS only: its Zenoh links to the other hosts (and so to the robots)
    // stay up.
    let ports: Vec<String> = hosts.servers.ports().iter().map(u16::to_string).collect();
    let ports = ports.join(",");
    let servers = hosts.servers.addresses().join(",");
    let cut = [
        ["OUTPUT", "-d", servers.as_str(), "--dports"],
        ["INPUT", "-s", servers.as_str(), "--sports"],
    ];
    let acks_at_cut = acks(&hosts.owner().http);
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
    let taken = hosts.standby_takes_over(cut_at);
    let acks_at_takeover = acks(&hosts.owner().http);
    std::thread::sleep(Duration::from_secs(5));
    let acks_later = acks(&hosts.owner().http);
    // The old owner keeps the site, acking nothing, while its renewals may yet be answered.
    let dropped = wait_for(Duration::from_secs(30), || {
        let text = http_get(&hosts.owner().http, "/metrics")?.1;
        (metric(&text, "levelmap_sites_dropped_total") == 1).then_some(cut_at.elapsed())
    })
    .expect("the owner drops the site once cut from NATS");
    eprintln!(
        "cut: the standby served the site {:.1} s after the cut, the owner dropped it {:.1} s \
         after; the owner's acks: {acks_at_cut} at the cut, {acks_at_takeover} when the \
         standby took over, {acks_later} 5 s later",
        taken.as_secs_f64(),
        dropped.as_secs_f64()
    );
    // Never two owners acking: none from the old owner once the standby has the site.
    assert_eq!(
        acks_at_takeover, acks_later,
        "the old owner acked after the standby took the site"
    );
    // Unrenewed for its lease (3 s) and the renewal grace (10 s), counted from its last
    // renewal, up to a round (a third of the lease's sleep, a third's timeout) before the
    // cut, and noticed at the end of a round: 17 s.
    assert!(
        dropped < Duration::from_secs(18),
        "the owner must drop the site within its lease and grace, took {dropped:?}"
    );
    assert_restored(&hosts.standby().http, &before);
    // The cut heals: the old owner appends nothing more (the standby holds the lease), and
    // gets the site back.
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
        summary_nodes(&hosts.owner().http).is_none(),
        "the old owner does not serve the site on its own once the cut heals"
    );
    hosts.every_node_once_back_home(edges);
    let fenced = metric(
        &http_get(&hosts.owner().http, "/metrics")
            .expect("metrics")
            .1,
        "levelmap_log_appends_fenced_total",
    );
    eprintln!("cut: the owner's appends fenced after the cut healed: {fenced}");
}
