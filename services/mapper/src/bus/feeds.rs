//! The robots' feeds a mapper takes from the bus: nodes (to the worker), live odometry and
//! live scans (to their callbacks, with no mapping work, so teleoperation sees them at once).
//! In single-machine mode one set for every fleet (`levelmap/*/robots/*/…`); in cluster mode
//! one set per site this host owns, declared once it took the site over and undeclared when
//! it drops it, so the routers carry a site's messages to its owner only.

use crate::inbox::Work;
use crate::views::{Metrics, Shared};
use anyhow::Result;
use std::sync::{Arc, mpsc};
use wire::Topic;

/// Declares the feeds of a fleet (or of every fleet).
#[derive(Clone)]
pub struct Feeds {
    session: zenoh::Session,
    shared: Arc<Shared>,
    /// The fleets configured: live messages of others are refused.
    fleets: Arc<[String]>,
    work: mpsc::SyncSender<Work>,
}

/// A fleet's feeds, declared while this is held (dropping it undeclares them).
pub struct Declared {
    _nodes: zenoh::pubsub::Subscriber<()>,
    _odometry: zenoh::pubsub::Subscriber<()>,
    _scans: zenoh::pubsub::Subscriber<()>,
}

/// The key chunk of every fleet.
pub const EVERY_FLEET: &str = "*";

impl Feeds {
    /// Feeds on `session`: nodes to `work`, live messages of `fleets` to `shared`.
    pub fn new(
        session: zenoh::Session,
        shared: Arc<Shared>,
        fleets: &[String],
        work: mpsc::SyncSender<Work>,
    ) -> Feeds {
        Feeds {
            session,
            shared,
            fleets: fleets.into(),
            work,
        }
    }

    /// The session the feeds are declared on.
    pub fn session(&self) -> &zenoh::Session {
        &self.session
    }

    /// Declares `fleet`'s feeds ([`EVERY_FLEET`]: every fleet's).
    pub async fn declare(&self, fleet: &str) -> Result<Declared> {
        let node_keys = format!("{}/{fleet}/robots/*/{}", wire::KEY_ROOT, Topic::Node);
        let (shed, work) = (self.shared.clone(), self.work.clone());
        let nodes = self
            .session
            .declare_subscriber(node_keys)
            .callback(move |sample| {
                Metrics::bump(&shed.metrics.nodes_received);
                let payload = sample.payload().to_bytes().into_owned();
                let node = Work::node(sample.key_expr().as_str(), payload);
                // Behind by a full queue: the node stays in its robot's outbox and comes
                // again (the next node's gap asks for it), instead of the mapper's memory
                // growing.
                if let Err(mpsc::TrySendError::Full(_)) = work.try_send(node) {
                    shed.metrics.reject("node", "queue_full");
                }
            })
            .await
            .map_err(anyhow::Error::from_boxed)?;
        let odometry = self
            .declare_live(fleet, Topic::Odom, crate::bus::odometry::on_odometry)
            .await?;
        let scans = self
            .declare_live(fleet, Topic::Scan, crate::bus::odometry::on_live_scan)
            .await?;
        Ok(Declared {
            _nodes: nodes,
            _odometry: odometry,
            _scans: scans,
        })
    }

    /// A subscription to one live topic of `fleet`'s robots, handled in its callback by
    /// `handle(shared, fleets configured, key, payload)`.
    async fn declare_live(
        &self,
        fleet: &str,
        topic: Topic,
        handle: fn(&Shared, &[String], &str, &[u8]),
    ) -> Result<zenoh::pubsub::Subscriber<()>> {
        let (live, known) = (self.shared.clone(), self.fleets.clone());
        self.session
            .declare_subscriber(format!("{}/{fleet}/robots/*/{topic}", wire::KEY_ROOT))
            .callback(move |sample| {
                handle(
                    &live,
                    &known,
                    sample.key_expr().as_str(),
                    &sample.payload().to_bytes(),
                )
            })
            .await
            .map_err(anyhow::Error::from_boxed)
    }
}
