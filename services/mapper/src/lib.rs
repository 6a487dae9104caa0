//! The levelmap mapping server: nodes from every robot of a fleet over Zenoh into one pose
//! network (scan matching within and between robots, GPS), each node committed to the
//! embedded store before it is acked, and the map served over HTTP.
//!
//! The domain: [`fleet`] (a fleet's map of checked nodes, pure), [`state`] (the views the
//! HTTP side reads), [`live`] (each robot's live feed), [`tiles`] (the map's
//! tiles for windows around robots), [`marginals`], [`versions`] (frozen maps). The disk: [`store`], [`restore`] (the store read back at start, and `--verify-store`). The shells: [`server`] (wiring),
//! [`worker`] (the ingest loop), [`odometry`] and [`bus`] (Zenoh in and out), [`recording`] (a
//! recording fed in as the bus's traffic), [`ros_out`] (the maps to ROS 2), [`api`] (HTTP).

pub mod api;
pub mod bus;
pub mod config;
pub mod fleet;
pub mod live;
pub mod localization;
pub mod marginals;
pub mod odometry;
pub mod recording;
pub mod restore;
pub mod ros_out;
pub mod server;
pub mod shared_log;
pub mod state;
pub mod store;
pub mod tiles;
pub mod versions;
pub mod worker;

/// The mapping code's version: what derives a fleet's edges and snapshot from its nodes,
/// with the parameters (`MapperConfig::mapping_version`). Raise the revision when a change
/// maps the same nodes to another network (a better IDC, a new closure test): stores
/// written before are then rebuilt from their nodes at start. An undeclared change is
/// caught too (the replayed edges differ from the stored ones) and rebuilt the same way.
pub const MAPPING_CODE: &str = concat!("levelmap ", env!("CARGO_PKG_VERSION"), " mapping r1");

pub use config::{MapperConfig, fleet_mapping_params};
pub use fleet::{FleetMap, IngestError, Ingested, NodeRecord, Sequence};
pub use server::{Running, start};
pub use store::{Store, StoreError};
