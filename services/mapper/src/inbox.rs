//! The mapping worker's inbox: what the bus, the HTTP API, a recording's feed and the
//! cluster's keepers hand the worker ([`Work`]), each answered on its own reply channel.

use crate::journal::ChangeError;
use fleetmap::FleetMap;
use std::collections::HashMap;
use std::sync::{Arc, mpsc};
use std::time::Instant;

/// Most messages waiting for the worker: nodes beyond it are shed (not acked, so their robots
/// send them again), which bounds the mapper's memory when it falls behind (1,024 nodes with
/// clouds are about 60 MB).
pub const INGEST_QUEUE: usize = 1024;

/// The answer to an operator's optimize request: the report as JSON, or why not.
pub type OptimizeReply = tokio::sync::oneshot::Sender<Result<serde_json::Value, OptimizeError>>;

/// Work for the mapping worker.
pub enum Work {
    /// A node as it came from the bus.
    Node {
        /// Its Zenoh key.
        key: String,
        /// Its bytes.
        payload: Vec<u8>,
        /// When it reached the mapper.
        received: Instant,
    },
    /// Finish this turn, then stop (the HTTP side may still hold senders).
    Stop,
    /// Re-optimize a fleet now.
    Optimize {
        /// The fleet.
        fleet: String,
        /// Where the report goes.
        reply: OptimizeReply,
    },
    /// A recording's feed: take a fleet's solve here (the recorded mapper took it here) and
    /// run it; it is applied at [`Work::ApplySolve`].
    TakeSolve {
        /// The fleet.
        fleet: String,
        /// Whether it was taken.
        reply: tokio::sync::oneshot::Sender<Result<(), OptimizeError>>,
    },
    /// A recording's feed: apply the fleet's solve taken before, here.
    ApplySolve {
        /// The fleet.
        fleet: String,
        /// Where the report goes.
        reply: OptimizeReply,
    },
    /// New modes of a fleet's robots (journaled already), with the maps of the versions they
    /// localize on (built off the worker).
    SetModes {
        /// The fleet.
        fleet: String,
        /// Its modes.
        modes: crate::localization::FleetModes,
        /// The map of each version the modes name.
        maps: HashMap<u64, Arc<slam::localize::LocalizationMap>>,
        /// Answered once the worker uses them.
        reply: tokio::sync::oneshot::Sender<()>,
    },
    /// `site` comes to this host (cluster mode: with its lease, its map restored from its
    /// log, which went to the journal first): map its nodes from now on.
    Adopt {
        /// The site (a fleet).
        site: String,
        /// Its map, restored.
        map: Box<FleetMap>,
        /// How many of its nodes the snapshot it was restored from covered.
        covered: usize,
        /// Answered once its nodes are taken.
        reply: tokio::sync::oneshot::Sender<()>,
    },
    /// A change of `site`'s versions or modes, checked by the API: journaled by the worker
    /// ([`crate::journal`]), as every change of a site's record is.
    Change {
        /// The site.
        site: String,
        /// The change (boxed: it is the largest of the work).
        change: Box<crate::store::SiteChange>,
        /// An added version's file (shared beyond the store already: [`crate::blobs`]).
        file: Option<Vec<u8>>,
        /// When the operator asked (names a change of modes in the log).
        asked_ns: u64,
        /// Answered once stored, or with why not.
        reply: tokio::sync::oneshot::Sender<Result<(), ChangeError>>,
    },
    /// `site` leaves this host (cluster mode: its lease was lost): drop it at once.
    Drop {
        /// The site.
        site: String,
        /// Answered once nothing of it is acked any more.
        reply: tokio::sync::oneshot::Sender<()>,
    },
}

/// Why an optimize request got no report.
#[derive(Debug, thiserror::Error)]
pub enum OptimizeError {
    /// The worker is gone: the mapper is stopping.
    #[error("the mapping worker stopped")]
    Stopped,
    /// The worker's queue is full: try again.
    #[error("the mapping worker is busy")]
    Busy,
    /// The worker refused: no such fleet, a network not anchored yet, a failed solve.
    #[error("{0}")]
    Refused(String),
    /// The store cannot commit (the solve's point would not be stored): try again later.
    #[error("{0}")]
    StoreFailed(String),
}

impl Work {
    /// A node received on `key`, as the Zenoh subscription and a recording's feed both hand
    /// it to the worker (which decodes and checks it).
    pub fn node(key: &str, payload: Vec<u8>) -> Work {
        Work::Node {
            key: key.to_owned(),
            payload,
            received: Instant::now(),
        }
    }

    /// Asks the worker behind `work` to re-optimize `fleet` now and waits for its report.
    pub async fn optimize(
        work: &mpsc::SyncSender<Work>,
        fleet: &str,
    ) -> Result<serde_json::Value, OptimizeError> {
        let (reply, answer) = tokio::sync::oneshot::channel();
        let fleet = fleet.to_owned();
        work.try_send(Work::Optimize { fleet, reply })
            .map_err(|e| match e {
                mpsc::TrySendError::Full(_) => OptimizeError::Busy,
                mpsc::TrySendError::Disconnected(_) => OptimizeError::Stopped,
            })?;
        answer.await.map_err(|_| OptimizeError::Stopped)?
    }
}
