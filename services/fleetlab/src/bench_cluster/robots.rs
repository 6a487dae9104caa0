//! The bench's robots: each publishes its nodes and odometry on a Zenoh client session that
//! lists every host's router (as a robot's config does), reads its acks, and keeps its
//! unacked nodes in memory as the edge's outbox keeps them on disk: re-sent after a second
//! without ack progress, the wait doubling up to 8 s while nothing answers (the edge's
//! [`ResendBackoff`]), and at once from where an ack asks (`resend_from`).

use crate::bench_fleet::{robot_publishers, wait_matched};
use anyhow::Result;
use edge::ResendBackoff;
use runtime::session::{Role, SessionConfig};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Session;
use zenoh::pubsub::{Publisher, Subscriber};

/// Re-sent at once, at most, as the edge's window.
const RESEND_WINDOW: usize = 64;

/// One robot's link to the mapper.
pub(super) struct Robot {
    pub name: String,
    /// Its site's index.
    pub site: usize,
    node: Publisher<'static>,
    odometry: Publisher<'static>,
    _acks: Subscriber<()>,
}

/// What a robot's acks have told it.
pub(super) struct AckState {
    /// The highest node acked (its chain holds every node up to it).
    pub acked: Option<u64>,
    /// Sent, not acked yet: the node as sent and when it was first sent.
    unacked: BTreeMap<u64, (Vec<u8>, Instant)>,
    /// An ack asked for the nodes from this one.
    resend_from: Option<u64>,
    backoff: ResendBackoff,
    /// When the ack last moved on (or the last re-send went out).
    since: Instant,
    pub resent: u64,
}

/// What an ack says, as the bench reads it.
#[derive(Clone, Copy)]
struct Ack {
    chain_id: u64,
    acked: Option<u64>,
    resend_from: Option<u64>,
}

/// When a site's ack moved on: for the time a moved site takes to ack again.
pub(super) type AckProgress = Arc<Mutex<Vec<(usize, Instant)>>>;

/// The robots, their sessions, and what their acks said.
pub(super) struct Robots {
    pub robots: Vec<Robot>,
    pub acks: Vec<Arc<Mutex<AckState>>>,
    pub progress: AckProgress,
    sessions: Vec<Session>,
}

impl Robots {
    /// `robots` robots on `sessions` client sessions; session `s` lists the routers from
    /// `routers[s % n]` on, so that the sessions spread over the hosts. Robot `r` is on site
    /// `r % sites.len()`. Returns once every robot's node publisher matches a subscriber.
    pub async fn connect(
        robots: usize,
        sessions: usize,
        routers: &[String],
        sites: &[String],
    ) -> Result<Robots> {
        let mut opened = Vec::new();
        for s in 0..sessions.min(robots).max(1) {
            let mut connect = routers.to_vec();
            connect.rotate_left(s % routers.len());
            let config = SessionConfig {
                connect: Some(connect),
                ..SessionConfig::client(&routers[0])
            };
            opened.push(config.open(Role::Client).await?);
        }
        let progress = AckProgress::default();
        let (mut linked, mut acks) = (Vec::new(), Vec::new());
        for r in 0..robots {
            let session = &opened[r % opened.len()];
            let (name, site) = (format!("robot{r}"), r % sites.len());
            let fleet = &sites[site];
            let state = Arc::new(Mutex::new(AckState::new()));
            let (on_ack, progress) = (state.clone(), progress.clone());
            let ack_subscriber = session
                .declare_subscriber(wire::ack_key(fleet, &name)?)
                .callback(move |sample| {
                    if let Ok(ack) = wire::decode_ack(&sample.payload().to_bytes()) {
                        let moved = on_ack.lock().expect("acks").take(Ack {
                            chain_id: ack.chain_id,
                            acked: ack.acked_node_seq,
                            resend_from: ack.resend_from,
                        });
                        if moved {
                            progress
                                .lock()
                                .expect("progress")
                                .push((site, Instant::now()));
                        }
                    }
                })
                .await
                .map_err(anyhow::Error::from_boxed)?;
            let (node, odometry) = robot_publishers(session, fleet, &name).await?;
            linked.push(Robot {
                name,
                site,
                node,
                odometry,
                _acks: ack_subscriber,
            });
            acks.push(state);
        }
        let deadline = Instant::now() + Duration::from_secs(30);
        for robot in &linked {
            wait_matched(&robot.node, &robot.name, deadline).await?;
        }
        Ok(Robots {
            robots: linked,
            acks,
            progress,
            sessions: opened,
        })
    }

    /// Sends robot `r`'s node `seq` (`bytes` as sent) and keeps it until acked.
    pub async fn send_node(&self, r: usize, seq: u64, bytes: Vec<u8>) {
        self.acks[r]
            .lock()
            .expect("acks")
            .unacked
            .insert(seq, (bytes.clone(), Instant::now()));
        // A put into a session whose router died is lost; the re-send brings it.
        let _ = self.robots[r].node.put(bytes).await;
    }

    /// Publishes robot `r`'s odometry; false when the session refused it.
    pub async fn send_odometry(&self, r: usize, bytes: Vec<u8>) -> bool {
        self.robots[r].odometry.put(bytes).await.is_ok()
    }

    /// Re-sends what robot `r`'s acks ask for or have left waiting too long.
    pub async fn resend_due(&self, r: usize) {
        let due = self.acks[r].lock().expect("acks").due(Instant::now());
        for bytes in due {
            let _ = self.robots[r].node.put(bytes).await;
        }
    }

    /// Closes the sessions.
    pub async fn close(self) -> Result<()> {
        drop(self.robots);
        for session in self.sessions {
            session.close().await.map_err(anyhow::Error::from_boxed)?;
        }
        Ok(())
    }
}

impl AckState {
    /// Nothing sent yet: re-sends after 1 s without progress, doubling up to 8 s (the edge's
    /// `resend_after_ms` and `resend_max_after_ms`).
    fn new() -> AckState {
        AckState {
            acked: None,
            unacked: BTreeMap::new(),
            resend_from: None,
            backoff: ResendBackoff::new(Duration::from_secs(1), Duration::from_secs(8)),
            since: Instant::now(),
            resent: 0,
        }
    }

    /// Takes an ack of the robot's chain (1); true when it acked more than before.
    fn take(&mut self, ack: Ack) -> bool {
        if ack.chain_id != 1 {
            return false;
        }
        if let Some(from) = ack.resend_from {
            self.resend_from = Some(from);
        }
        let Some(acked) = ack.acked else {
            return false;
        };
        if self.acked.is_some_and(|a| a >= acked) {
            return false;
        }
        self.acked = Some(acked);
        self.unacked = self.unacked.split_off(&(acked + 1));
        self.backoff.reset();
        self.since = Instant::now();
        true
    }

    /// The nodes to send again now, the window from where an ack asked or, after a wait
    /// without progress, from the oldest unacked.
    fn due(&mut self, now: Instant) -> Vec<Vec<u8>> {
        let wait = self.backoff.wait();
        let from = match self.resend_from.take() {
            Some(from) => from,
            None => {
                let Some((&oldest, (_, first_sent))) = self.unacked.first_key_value() else {
                    return Vec::new();
                };
                if now < self.since + wait || now < *first_sent + wait {
                    return Vec::new();
                }
                self.backoff.resent();
                self.since = now;
                oldest
            }
        };
        let window: Vec<Vec<u8>> = self
            .unacked
            .range(from..)
            .take(RESEND_WINDOW)
            .map(|(_, (bytes, _))| bytes.clone())
            .collect();
        self.resent += window.len() as u64;
        window
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ack(acked: Option<u64>, resend_from: Option<u64>) -> Ack {
        Ack {
            chain_id: 1,
            acked,
            resend_from,
        }
    }

    #[test]
    fn unacked_nodes_are_sent_again_after_a_wait_that_doubles_and_at_once_when_asked() {
        let mut state = AckState::new();
        let t0 = Instant::now();
        for seq in 0..3 {
            state.unacked.insert(seq, (vec![seq as u8], t0));
        }
        assert!(state.due(t0).is_empty(), "sent just now");
        // An ack of 0 moves on: 1 and 2 wait again from now.
        assert!(state.take(ack(Some(0), None)));
        assert!(
            !state.take(ack(Some(0), None)),
            "the same ack again is no progress"
        );
        let start = state.since;
        assert!(state.due(start + Duration::from_millis(900)).is_empty());
        assert_eq!(
            state.due(start + Duration::from_secs(1)),
            [vec![1], vec![2]]
        );
        // No progress: the next re-send waits 2 s.
        let later = start + Duration::from_secs(1);
        assert!(state.due(later + Duration::from_millis(1900)).is_empty());
        assert_eq!(state.due(later + Duration::from_secs(2)).len(), 2);
        // Asked from 2: at once, whatever the wait.
        assert!(!state.take(ack(Some(0), Some(2))));
        assert_eq!(state.due(later + Duration::from_secs(2)), [vec![2]]);
        assert_eq!(state.resent, 5);
        // Another chain's ack is not this robot's.
        let mut other = ack(Some(2), None);
        other.chain_id = 7;
        assert!(!state.take(other));
        assert!(state.take(ack(Some(2), None)));
        assert!(state.unacked.is_empty());
    }
}
