//! The worker's turn alone: nodes in through its inbox, the entries it journals and the acks
//! it sends out, with a journal and an outbound of the test's own (no Zenoh, no redb).

use super::Worker;
use crate::bus::{AckOf, Outbound};
use crate::config::MapperConfig;
use crate::inbox::Work;
use crate::journal::{ChangeError, Journal, SiteFault};
use crate::store::{FleetBatch, SiteChange, StoreError};
use crate::views::{Metrics, Shared};
use fleetmap::{FleetMap, SnapshotCovers};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant};

/// What the worker did, in its order: entries journaled and acks sent.
#[derive(Clone, Debug, PartialEq)]
enum Event {
    /// A site's nodes made durable, by arrival index.
    Journaled(String, Vec<u64>),
    /// A change made durable.
    Changed(String, SiteChange),
    /// A robot's chain acked up to a node.
    Acked(String, String, Option<u64>),
    /// A site dropped from the journal.
    Dropped(String),
}

type Events = Arc<Mutex<Vec<Event>>>;

/// A journal that keeps its entries in memory; a site's commits fail with its fault while
/// one is set.
struct TestJournal {
    events: Events,
    faults: Arc<Mutex<HashMap<String, SiteFault>>>,
    dropped: Vec<String>,
}

impl Journal for TestJournal {
    fn holds(&self, site: &str) -> bool {
        !self.dropped.iter().any(|d| d == site)
    }

    fn commit(
        &mut self,
        batches: &mut Vec<FleetBatch<'_>>,
    ) -> Result<Vec<(String, SiteFault)>, StoreError> {
        let faults = self.faults.lock().unwrap().clone();
        let mut failed = Vec::new();
        for batch in batches.iter() {
            match faults.get(batch.fleet) {
                Some(fault) => failed.push((batch.fleet.to_owned(), fault.clone())),
                None if !batch.nodes.is_empty() => {
                    let arrivals = batch.nodes.iter().map(|(a, _)| *a).collect();
                    let entry = Event::Journaled(batch.fleet.to_owned(), arrivals);
                    self.events.lock().unwrap().push(entry);
                }
                None => {}
            }
        }
        batches.retain(|b| !faults.contains_key(b.fleet));
        failed.dedup();
        Ok(failed)
    }

    fn change(
        &mut self,
        site: &str,
        change: &SiteChange,
        _file: Option<Vec<u8>>,
        _asked_ns: u64,
    ) -> Result<(), ChangeError> {
        let entry = Event::Changed(site.to_owned(), change.clone());
        self.events.lock().unwrap().push(entry);
        Ok(())
    }

    fn drop_site(&mut self, site: &str) {
        self.dropped.push(site.to_owned());
        self.events
            .lock()
            .unwrap()
            .push(Event::Dropped(site.to_owned()));
    }

    fn snapshot(&self, _: &str, _: SnapshotCovers, _: Vec<u8>) -> Result<(), StoreError> {
        Ok(())
    }
}

/// Acks into the events, and to the test as they are sent.
struct TestBus {
    events: Events,
    acks: Mutex<mpsc::Sender<Event>>,
}

impl Outbound for TestBus {
    fn ack(&self, _: &Metrics, of: &AckOf) {
        let ack = Event::Acked(of.fleet.into(), of.robot.into(), of.acked);
        self.events.lock().unwrap().push(ack.clone());
        let _ = self.acks.lock().unwrap().send(ack);
    }
    fn localization(&self, _: &Metrics, _: &wire::Localized) {}
    fn publish_poses(&self, _: &FleetMap, _: &[(String, u64)]) {}
}

/// A worker on its thread over sites `a` and `b`.
struct Running {
    work: mpsc::SyncSender<Work>,
    acks: mpsc::Receiver<Event>,
    events: Events,
    faults: Arc<Mutex<HashMap<String, SiteFault>>>,
    shared: Arc<Shared>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Running {
    fn start() -> Running {
        let config = MapperConfig {
            fleets: vec!["a".into(), "b".into()],
            store: crate::config::StoreConfig {
                snapshot_every_nodes: 0,
            },
            solve_interval_ms: 50,
            ..MapperConfig::default()
        };
        let events = Events::default();
        let faults = Arc::new(Mutex::new(HashMap::new()));
        let journal = TestJournal {
            events: events.clone(),
            faults: faults.clone(),
            dropped: Vec::new(),
        };
        let (acks_tx, acks) = mpsc::channel();
        let bus = TestBus {
            events: events.clone(),
            acks: Mutex::new(acks_tx),
        };
        let shared = Arc::new(Shared::new(String::new(), 0));
        let worker = Worker::new(
            config,
            HashMap::new(),
            HashMap::new(),
            shared.clone(),
            Box::new(bus),
            Box::new(journal),
        );
        let (work, inbox) = mpsc::sync_channel(64);
        let thread = std::thread::spawn(move || worker.run(&inbox));
        Running {
            work,
            acks,
            events,
            faults,
            shared,
            thread: Some(thread),
        }
    }

    fn send(&self, site: &str, seq: u64) {
        let key = wire::node_key(site, "r0").unwrap();
        self.work.send(Work::node(&key, node(site, seq))).unwrap();
    }

    /// Waits for `site`'s robot to be acked up to `seq` (at any time since the start).
    fn acked_up_to(&self, site: &str, seq: u64) {
        let deadline = Instant::now() + Duration::from_secs(10);
        let want = Event::Acked(site.into(), "r0".into(), Some(seq));
        while !self.events().contains(&want) {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                panic!("{site} never acked up to {seq}: {:?}", self.events());
            }
            let _ = self.acks.recv_timeout(left.min(Duration::from_millis(50)));
        }
    }

    /// Whether `site` was acked in `events`.
    fn acks_of(events: &[Event], site: &str) -> usize {
        events
            .iter()
            .filter(|e| matches!(e, Event::Acked(s, ..) if s == site))
            .count()
    }

    fn events(&self) -> Vec<Event> {
        self.events.lock().unwrap().clone()
    }

    fn stop(mut self) -> Vec<Event> {
        self.work.send(Work::Stop).unwrap();
        self.thread.take().unwrap().join().unwrap();
        self.events()
    }
}

/// Node `seq` of robot r0 of `site`, `seq` m along, encoded.
fn node(site: &str, seq: u64) -> Vec<u8> {
    fleetmap::testing::node_of(site, "r0", 7, seq, 0, seq as f64).encode()
}

/// Every arrival index journaled for `site`, in order.
fn journaled(events: &[Event], site: &str) -> Vec<u64> {
    events
        .iter()
        .filter_map(|e| match e {
            Event::Journaled(s, arrivals) if s == site => Some(arrivals.clone()),
            _ => None,
        })
        .flatten()
        .collect()
}

/// Where in `events` an event is.
fn position(events: &[Event], event: &Event) -> usize {
    events
        .iter()
        .position(|e| e == event)
        .unwrap_or_else(|| panic!("{event:?} not in {events:?}"))
}

/// The event where `site`'s node `arrival` was journaled.
fn journaled_at(events: &[Event], site: &str, arrival: u64) -> usize {
    events
        .iter()
        .position(|e| matches!(e, Event::Journaled(s, a) if s == site && a.contains(&arrival)))
        .unwrap_or_else(|| panic!("{site}'s node {arrival} never journaled: {events:?}"))
}

#[test]
fn a_turn_journals_each_sites_nodes_before_it_acks_them() {
    let running = Running::start();
    for seq in 0..3 {
        running.send("a", seq);
        running.send("b", seq);
    }
    running.acked_up_to("a", 2);
    running.acked_up_to("b", 2);
    let events = running.stop();
    for site in ["a", "b"] {
        assert_eq!(
            journaled(&events, site),
            vec![0, 1, 2],
            "{site}: {events:?}"
        );
        for seq in 0..3 {
            let ack = Event::Acked(site.into(), "r0".into(), Some(seq));
            if let Some(acked) = events.iter().position(|e| *e == ack) {
                assert!(journaled_at(&events, site, seq) < acked, "{events:?}");
            }
        }
    }
}

#[test]
fn a_site_whose_journal_fails_waits_alone_and_is_acked_once_it_takes_the_entries() {
    let running = Running::start();
    running.send("a", 0);
    running.send("b", 0);
    running.acked_up_to("a", 0);
    running.acked_up_to("b", 0);
    let unavailable = SiteFault::Unavailable("no leader".into());
    running
        .faults
        .lock()
        .unwrap()
        .insert("b".into(), unavailable);
    running.send("b", 1);
    running.send("a", 1);
    running.acked_up_to("a", 1);
    // While b's journal fails: a is acked, b's node waits, and b's next one is refused
    // (its robot sends it again).
    let mark = running.events().len();
    running.send("b", 2);
    running.send("a", 2);
    running.acked_up_to("a", 2);
    std::thread::sleep(Duration::from_millis(1500));
    let during = running.events()[mark..].to_vec();
    assert_eq!(
        Running::acks_of(&during, "b"),
        0,
        "b acked while its journal failed: {during:?}"
    );
    assert_eq!(journaled(&running.events(), "b"), vec![0]);
    let refused = running.shared.metrics.rejected("node", "store");
    assert!(refused >= 1, "b's node 2 was not refused while b waited");
    running.faults.lock().unwrap().clear();
    // The retry (every second) journals b's node 1 and acks it; the robot sends 2 again.
    running.acked_up_to("b", 1);
    running.send("b", 2);
    running.acked_up_to("b", 2);
    let events = running.stop();
    assert_eq!(journaled(&events, "b"), vec![0, 1, 2], "{events:?}");
    assert_eq!(journaled(&events, "a"), vec![0, 1, 2], "{events:?}");
    let b1 = Event::Acked("b".into(), "r0".into(), Some(1));
    assert!(journaled_at(&events, "b", 1) < position(&events, &b1));
}

#[test]
fn a_fenced_site_is_dropped_with_what_it_held_and_the_others_go_on() {
    let running = Running::start();
    running.send("a", 0);
    running.send("b", 0);
    running.acked_up_to("b", 0);
    let fenced = SiteFault::Fenced("another host appended".into());
    running.faults.lock().unwrap().insert("b".into(), fenced);
    let mark = running.events().len();
    running.send("b", 1);
    running.send("a", 1);
    running.acked_up_to("a", 1);
    running.send("b", 2);
    running.send("a", 2);
    running.acked_up_to("a", 2);
    let after = running.events()[mark..].to_vec();
    assert_eq!(
        Running::acks_of(&after, "b"),
        0,
        "b acked after its fence: {after:?}"
    );
    assert!(running.shared.metrics.rejected("node", "not_owner") >= 1);
    let view = running.shared.fleet("b");
    assert!(view.is_none(), "b's view stays after its drop");
    let events = running.stop();
    assert!(events.contains(&Event::Dropped("b".into())), "{events:?}");
    assert_eq!(journaled(&events, "b"), vec![0]);
}

#[test]
fn a_change_is_journaled_by_the_worker_and_answered_once_durable() {
    let running = Running::start();
    let (reply, done) = tokio::sync::oneshot::channel();
    let change = SiteChange::ModesSet {
        robots: None,
        version: 0,
    };
    let work = Work::Change {
        site: "a".into(),
        change: Box::new(change.clone()),
        file: None,
        asked_ns: 1,
        reply,
    };
    running.work.send(work).unwrap();
    done.blocking_recv().unwrap().unwrap();
    let events = running.stop();
    assert_eq!(events, vec![Event::Changed("a".into(), change)]);
}
