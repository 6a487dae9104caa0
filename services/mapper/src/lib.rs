//! The levelmap mapping server: nodes from every robot of a fleet over Zenoh into one pose
//! network (scan matching within and between robots, GPS), each node committed to the
//! embedded store before it is acked, and the map served over HTTP.
//!
//! The map itself (a fleet's `FleetMap`, its snapshot, views, tiles, marginals) is the pure
//! `fleetmap` crate; this crate is its shell, in rooms:
//! - [`bus`]: Zenoh in and out (acks, corrected poses, live odometry and scans), a recording
//!   fed in as the bus's traffic, the maps to ROS 2;
//! - [`worker`]: the ingest loop (check, map, journal, ack, solve), on its own thread, the
//!   single writer; [`inbox`] what it is handed; [`journal`] the one seam through which it
//!   makes every change of a site's record durable; [`blobs`] what a host shares beside it;
//! - [`store`]: the durable store (redb); [`restore`] the store read back at start (also
//!   `--verify-store`), [`mapping`] what a fleet is mapped with;
//! - [`views`]: what the HTTP side reads (each fleet's `FleetView`, metrics, events, each
//!   robot's live feed);
//! - [`api`]: the HTTP API; [`localization`] (robots localizing on a map version) and
//!   [`versions`] (frozen maps) serve both the worker and the API;
//! - [`deployment`]: how the mapper is deployed: alone ([`deployment::Alone`]), or as one
//!   host of a cluster by the `cluster` crate (which this crate does not depend on), its
//!   stateless HTTP front the `gateway` crate;
//! - [`server`] wires them; [`config`] is the configuration; [`tokens`] the bearer tokens.

pub mod api;
pub mod blobs;
pub mod bus;
pub mod config;
pub mod deployment;
pub mod inbox;
pub mod journal;
pub mod localization;
pub mod mapping;
pub mod restore;
pub mod server;
pub mod tokens;
pub use mapstore as store;
pub mod versions;
pub mod views;
pub mod worker;

pub use config::{MapperConfig, fleet_mapping_params};
pub use fleetmap::{FleetMap, IngestError, Ingested, NodeRecord, Sequence};
pub use server::{Running, start, start_deployed};
pub use store::{Store, StoreError};
