//! Partition drill (issue 14): robots reach the mapper through a network namespace (a veth
//! pair) and drive through 60 s of 20 % packet loss each way, a 10 s cut and a 30 s half-open
//! connection (the mapper's side silently dropping everything while the robots' side sees an
//! established connection). Nothing is lost or mapped twice, and each robot's link comes back
//! by itself after each phase.
//!
//! Needs root, `ip` (iproute2) and `iptables`: namespaces, veth and iptables' `statistic` match
//! (`tc netem` is not in every kernel). Without them the test fails saying so; it never skips.
//! Its figures are one JSON line on stderr (`-- --nocapture`).

mod common;

use common::netns::{Namespace, Netns, require_root_and_tools, run};
use common::*;
use serde_json::json;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const ROBOTS: usize = 2;
const LOSS: Duration = Duration::from_secs(60);
const LOSS_PROBABILITY: &str = "0.2";
const CUT: Duration = Duration::from_secs(10);
const HALF_OPEN: Duration = Duration::from_secs(30);
/// The longest a robot may take to get a node into the map once a phase ends. Zenoh closes a
/// dead transport (a put blocked 5 s, or its 10 s lease) and dials again, 1–4 s apart, each
/// attempt up to 10 s with its SYNs retransmitted: one gets through once the phase ends.
const RECOVERY_BOUND: Duration = Duration::from_secs(30);
/// What was in flight when a phase began reaches the map within this (the mapper's worker
/// commits in batches).
const SETTLE: Duration = Duration::from_secs(3);
/// 640 s of park at 4x: 160 s of driving, through every phase (about a node a second).
const SIM_DURATION_S: f64 = 640.0;
const SPEED: f64 = 4.0;

/// The robots' network: a namespace and a veth pair to the root namespace, with the iptables
/// rules of each phase. Dropping it removes the root namespace's rules and the namespace
/// (with the veth pair), also when the test fails.
struct Partition {
    net: Netns,
    /// Root-namespace rules in place (chain and match), deleted on drop.
    host_rules: Vec<Vec<String>>,
}

impl Partition {
    fn create() -> Partition {
        Partition {
            net: Netns::create("partition"),
            host_rules: Vec::new(),
        }
    }

    /// `iptables` inside the robots' namespace.
    fn robot_side(&self, args: &[&str]) {
        self.net.iptables(args);
    }

    /// The mapper's side stops answering: everything from and to the robots' veth is dropped
    /// in the root namespace, silently (no reset, no unreachable).
    fn drop_on_mapper_side(&mut self) {
        for (chain, direction) in [("INPUT", "-i"), ("OUTPUT", "-o")] {
            let rule: Vec<String> = [chain, direction, &self.net.host_if, "-j", "DROP"]
                .map(String::from)
                .into();
            let mut args = vec!["-I"];
            args.extend(rule.iter().map(String::as_str));
            run("iptables", &args);
            self.host_rules.push(rule);
        }
    }

    fn restore_mapper_side(&mut self) {
        for rule in std::mem::take(&mut self.host_rules) {
            let mut args = vec!["-D"];
            args.extend(rule.iter().map(String::as_str));
            run("iptables", &args);
        }
    }

    /// Packets the DROP rules of `chain` dropped: inside the namespace (`ns`), or on the
    /// mapper's side of the veth (the root namespace's rules on it).
    fn dropped(&self, ns: bool, chain: &str) -> u64 {
        let listing = if ns {
            run(
                "ip",
                &[
                    "netns",
                    "exec",
                    &self.net.ns,
                    "iptables",
                    "-L",
                    chain,
                    "-v",
                    "-n",
                    "-x",
                ],
            )
        } else {
            run("iptables", &["-L", chain, "-v", "-n", "-x"])
        };
        // Lines: pkts bytes target prot opt in out source destination …
        listing
            .lines()
            .skip(2)
            .map(|l| l.split_whitespace().collect::<Vec<_>>())
            .filter(|f| f.get(2) == Some(&"DROP") && (ns || f.contains(&self.net.host_if.as_str())))
            .map(|f| f[0].parse::<u64>().expect("a packet count"))
            .sum()
    }

    /// TCP connections the robots' side holds as established to the mapper.
    fn established(&self) -> usize {
        run(
            "ip",
            &[
                "netns",
                "exec",
                &self.net.ns,
                "ss",
                "-Htn",
                "state",
                "established",
                "dst",
                &self.net.host_ip,
            ],
        )
        .lines()
        .count()
    }

    /// A robot's edge service inside the namespace (`ip netns exec` runs the same command
    /// there), its log in `dir`.
    fn spawn_edge(&self, dir: &Path, robot: usize, connect: &str) -> KillOnDrop {
        let source = format!("[source.sim]\nloop_index = {robot}\nduration_s = {SIM_DURATION_S}\n");
        let edge = edge_command(dir, robot, connect, SPEED, &source);
        let log = std::fs::File::create(dir.join(format!("robot{robot}.log"))).expect("log");
        self.net
            .wrap(&edge)
            .stdout(Stdio::piped())
            .stderr(log)
            .spawn()
            .map(KillOnDrop::from)
            .expect("levelmap edge starts in the namespace")
    }
}

impl Drop for Partition {
    fn drop(&mut self) {
        for rule in self.host_rules.drain(..) {
            let _ = Command::new("iptables").arg("-D").args(&rule).output();
        }
        // `net` goes next, with the veth pair, once no process is left inside: the edges
        // (`KillOnDrop`) are dropped before it, since a process left in the namespace would
        // keep the namespace and its veth pair alive.
    }
}

/// Each robot's nodes in the map.
fn mapped(http: &str) -> Vec<usize> {
    let graph = wait_for(Duration::from_secs(10), || {
        get_json(http, "/api/v1/fleets/park/graph")
    })
    .expect("the mapper's graph");
    let nodes = graph["nodes"].as_array().expect("nodes");
    (0..ROBOTS)
        .map(|r| {
            let robot = format!("robot{r}");
            nodes.iter().filter(|n| n["robot"] == robot).count()
        })
        .collect()
}

/// Seconds from `since` until each robot has more nodes in the map than `before`: its link
/// came back by itself. Fails after [`RECOVERY_BOUND`].
fn recovery(http: &str, phase: &str, before: &[usize], since: Instant) -> Vec<f64> {
    let mut seconds: Vec<Option<f64>> = vec![None; ROBOTS];
    let recovered = wait_for(RECOVERY_BOUND, || {
        for (r, now) in mapped(http).into_iter().enumerate() {
            if seconds[r].is_none() && now > before[r] {
                seconds[r] = Some((since.elapsed().as_secs_f64() * 10.0).round() / 10.0);
            }
        }
        seconds.iter().all(Option::is_some).then_some(())
    });
    assert!(
        recovered.is_some(),
        "after the {phase}, a robot's link did not come back within {RECOVERY_BOUND:?}: \
         mapped {before:?} at the end, recovered after {seconds:?} s"
    );
    seconds.into_iter().map(Option::unwrap_or_default).collect()
}

/// `during` stayed `before` for every robot: the phase really kept nodes from the map.
fn assert_held(phase: &str, before: &[usize], during: &[usize]) {
    assert_eq!(
        before, during,
        "nodes reached the map during the {phase}: it did not cut the link"
    );
}

#[test]
fn robots_ride_out_loss_a_cut_and_a_half_open_link_by_themselves() {
    require_root_and_tools();
    let dir = temp_dir("partition");
    let mut net = Partition::create();
    let zenoh = format!("tcp/{}:{}", net.net.host_ip, free_port());
    let mapper = MapperProcess::start_on(&dir, zenoh.clone());
    let http = mapper.http.clone();
    eprintln!(
        "partition drill: namespace {}, mapper on {zenoh}, logs in {}",
        net.net.ns,
        dir.display()
    );
    let started = Instant::now();
    // The edges' logs are stamped in UTC: this is +0.0 s below.
    eprintln!(
        "partition drill: +0.0 s is {:.1} s after the Unix epoch",
        runtime::session::now_ns() as f64 * 1e-9
    );
    let mut edges: Vec<KillOnDrop> = (0..ROBOTS)
        .map(|r| net.spawn_edge(&dir, r, &zenoh))
        .collect();
    wait_for(Duration::from_secs(60), || {
        mapped(&http).iter().all(|&n| n >= 2).then_some(())
    })
    .expect("every robot's nodes reach the map through the namespace");

    // Phase marks, to read beside the edges' logs.
    let mark = |what: &str| {
        eprintln!(
            "partition drill: +{:.1} s {what}",
            started.elapsed().as_secs_f64()
        )
    };
    mark("first nodes mapped");

    // 1. Random loss both ways, inside the namespace.
    let loss_rule = [
        "-m",
        "statistic",
        "--mode",
        "random",
        "--probability",
        LOSS_PROBABILITY,
    ];
    let at_loss = mapped(&http);
    for chain in ["INPUT", "OUTPUT"] {
        net.robot_side(&[&["-A", chain], &loss_rule[..], &["-j", "DROP"]].concat());
    }
    mark("loss begins");
    std::thread::sleep(LOSS);
    let loss_dropped = [net.dropped(true, "INPUT"), net.dropped(true, "OUTPUT")];
    for chain in ["INPUT", "OUTPUT"] {
        net.robot_side(&[&["-D", chain], &loss_rule[..], &["-j", "DROP"]].concat());
    }
    let loss_ended = Instant::now();
    mark("loss ends");
    let after_loss = mapped(&http);
    assert!(
        loss_dropped.iter().all(|&d| d > 0),
        "the loss dropped nothing (in, out): {loss_dropped:?}"
    );
    let through_loss: Vec<usize> = (0..ROBOTS).map(|r| after_loss[r] - at_loss[r]).collect();
    assert!(
        through_loss.iter().all(|&n| n > 0),
        "nodes mapped through the loss: {through_loss:?}"
    );
    let loss_recovery = recovery(&http, "loss", &after_loss, loss_ended);

    // 2. A cut: everything dropped inside the namespace.
    for chain in ["INPUT", "OUTPUT"] {
        net.robot_side(&["-I", chain, "-j", "DROP"]);
    }
    mark("cut begins");
    std::thread::sleep(SETTLE);
    let at_cut = mapped(&http);
    std::thread::sleep(CUT - SETTLE);
    let after_cut = mapped(&http);
    let cut_dropped = [net.dropped(true, "INPUT"), net.dropped(true, "OUTPUT")];
    for chain in ["INPUT", "OUTPUT"] {
        net.robot_side(&["-D", chain, "-j", "DROP"]);
    }
    let cut_ended = Instant::now();
    mark("cut ends");
    assert_held("cut", &at_cut, &after_cut);
    assert!(
        cut_dropped[1] > 0,
        "the cut dropped nothing the robots sent: {cut_dropped:?}"
    );
    let cut_recovery = recovery(&http, "cut", &after_cut, cut_ended);

    // 3. Half-open: the mapper's side drops everything, the robots' side still holds an
    // established connection and keeps writing into it.
    net.drop_on_mapper_side();
    mark("half-open begins");
    // Nothing tells the robots: a second in, their connections are still established (a reset
    // or an unreachable would have ended them at once).
    std::thread::sleep(Duration::from_secs(1));
    let established = net.established();
    assert!(
        established >= ROBOTS,
        "the robots' side sees its connections ({established}) as established"
    );
    std::thread::sleep(SETTLE - Duration::from_secs(1));
    let at_half_open = mapped(&http);
    std::thread::sleep(HALF_OPEN - SETTLE);
    let after_half_open = mapped(&http);
    let half_open_dropped = [net.dropped(false, "INPUT"), net.dropped(false, "OUTPUT")];
    net.restore_mapper_side();
    let half_open_ended = Instant::now();
    mark("half-open ends");
    assert_held("half-open link", &at_half_open, &after_half_open);
    assert!(
        half_open_dropped[0] > 0,
        "the mapper's side dropped nothing from the robots: {half_open_dropped:?}"
    );
    let half_open_recovery = recovery(&http, "half-open link", &after_half_open, half_open_ended);

    // The robots finish driving and stay until every node is acked.
    let reports: Vec<serde_json::Value> = edges
        .drain(..)
        .map(|edge| edge_report(edge, Duration::from_secs(300)))
        .collect();
    let total_s = started.elapsed().as_secs_f64();
    for (r, report) in reports.iter().enumerate() {
        let robot = format!("robot{r}");
        assert_eq!(report["outbox_pending"], 0, "{robot}: {report}");
        let made = report["nodes"].as_u64().expect("nodes");
        let last = report["acked_node_seq"].as_u64().expect("acked");
        assert_eq!(
            made,
            last + 1,
            "{robot}: every node made is acked: {report}"
        );
        assert_eq!(
            node_seqs(&http, "park", &robot),
            (0..made).collect::<Vec<_>>(),
            "{robot}: every node made, once, in order"
        );
        // 30 s of driving is about 30 nodes the half-open link kept back.
        assert!(
            made as usize >= after_half_open[r] + 10,
            "{robot} drove through the half-open link: {made} made, {} mapped at its end",
            after_half_open[r]
        );
        assert!(
            report["node_resends"].as_u64().unwrap() > 0,
            "{robot}: nodes lost in the cut are sent again: {report}"
        );
    }
    // What the re-sends cost the mapper: nodes it had already (re-acked, not mapped) and
    // nodes after a gap (dropped, asked for again).
    let (_, metrics) = http_get(&http, "/metrics").expect("metrics");
    let duplicates = metric(&metrics, "levelmap_nodes_duplicate_total");
    let out_of_order = metric(
        &metrics,
        "levelmap_rejected_total{topic=\"node\",reason=\"out_of_order\"}",
    );
    let per_robot = |key: &str| -> Vec<u64> {
        reports
            .iter()
            .map(|r| r[key].as_u64().unwrap_or_default())
            .collect()
    };
    let figures = json!({
        "drill": "partition",
        "robots": ROBOTS,
        "nodes": per_robot("nodes"),
        "node_sends": per_robot("node_sends"),
        "node_resends": per_robot("node_resends"),
        "mapper_duplicates": duplicates,
        "mapper_out_of_order": out_of_order,
        "phases": [
            {
                "phase": "loss",
                "seconds": LOSS.as_secs(),
                "probability": LOSS_PROBABILITY,
                "dropped_packets_in_out": loss_dropped,
                "mapped_during": through_loss,
                "recovery_s": loss_recovery,
            },
            {
                "phase": "cut",
                "seconds": CUT.as_secs(),
                "dropped_packets_in_out": cut_dropped,
                "recovery_s": cut_recovery,
            },
            {
                "phase": "half-open",
                "seconds": HALF_OPEN.as_secs(),
                "established_at_start": established,
                "dropped_packets_in_out": half_open_dropped,
                "recovery_s": half_open_recovery,
            },
        ],
        "total_s": (total_s * 10.0).round() / 10.0,
    });
    eprintln!("partition drill figures: {figures}");
    drop(edges);
    drop(mapper);
    drop(net);
    std::fs::remove_dir_all(&dir).ok();
}
