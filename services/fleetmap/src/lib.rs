//! levelmap's map core: one fleet's map of checked nodes into one pose network (scan
//! matching within and between robots, GPS), pure: no async, no network, no store, no
//! clock but the tile cache's ages. The mapper (`services/mapper`) is its shell: it feeds
//! nodes from Zenoh, stores them, and serves what this crate computes.
//!
//! - [`fleet`]: [`FleetMap`], a fleet's map (nodes in chains, localized and passed spans,
//!   coverage), and its snapshot (`FleetMap::snapshot`, `FleetMap::restore`);
//! - [`view`]: [`FleetView`], the map at one moment for readers, sharing what did not change
//!   with the view before it ([`shared_log`]);
//! - [`tiles`]: the map cut into cached tiles for windows around robots;
//! - [`marginals`]: nodes' marginal covariances from a view;
//! - [`versions`]: a view frozen into a map version, and a version file taken in;
//! - [`localization`]: robots' modes, a version's map, and the trackers of robots that
//!   localize on a version instead of mapping.

pub mod fleet;
pub mod localization;
pub mod marginals;
pub mod shared_log;
pub mod tiles;
pub mod versions;
pub mod view;

#[cfg(any(test, feature = "testing"))]
pub mod testing;

/// The mapping code's version: what derives a fleet's edges and snapshot from its nodes
/// (this crate and `slam`), with the parameters (the mapper's `MapperConfig::mapping_version`).
/// Raise the revision when a change maps the same nodes to another network (a better IDC, a
/// new closure test): stores written before are then rebuilt from their nodes at start. An
/// undeclared change is caught too (the replayed edges differ from the stored ones) and
/// rebuilt the same way.
pub const MAPPING_CODE: &str = concat!("levelmap ", env!("CARGO_PKG_VERSION"), " mapping r4");

pub use fleet::{
    ChainRecord, FleetMap, IngestError, Ingested, LocalizedSpan, MAX_CHAINS_PER_ROBOT,
    MAX_ROBOTS_PER_FLEET, NodeRecord, RobotRecord, Sequence, SnapshotCovers, SolvePoint,
    SpanReplay, grid_of,
};
pub use view::{ChainView, FleetView, RobotView};
