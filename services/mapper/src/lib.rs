//! The levelmap mapping server: nodes from every robot of a fleet over Zenoh into one pose
//! network (scan matching within and between robots, GPS), each node committed to the
//! embedded store before it is acked, and the map served over HTTP.
//!
//! [`fleet`] is the pure mapping of wire nodes; [`store`] the disk; [`server`] and [`api`]
//! the thin Zenoh and HTTP shells.

pub mod api;
pub mod config;
pub mod fleet;
pub mod server;
pub mod state;
pub mod store;

pub use config::{MapperConfig, fleet_mapping_params};
pub use fleet::{FleetMap, IngestError, Ingested, NodeRecord, Sequence};
pub use server::{Running, start};
pub use store::{Store, StoreError};
