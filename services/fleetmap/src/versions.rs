//! Map versions: a fleet's map frozen as it is at one moment (every node's pose and leveled
//! scan, the GPS datum, the occupancy grid), kept unchanged in the store under a number and
//! served as one file (`wire::encode_map_version_file`). A version is the unit a fleet
//! rolls out; `levelmap map export` and `import` move it between mappers.
//!
//! A version is made from the fleet's current view (pure: the mapper stores it, numbered).

use crate::view::FleetView;
use serde::{Deserialize, Serialize};
use slam::geodesy::Geodetic;
use std::collections::BTreeSet;
use wire::{MapVersion, VersionNode, VersionOrigin, WireError};

/// A version in numbers, as the API lists it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct VersionSummary {
    /// The fleet.
    pub fleet: String,
    /// Its number in the fleet, from 1; never given again after a delete.
    pub version: u64,
    /// When the map was frozen (ns since the Unix epoch), in the mapper that froze it.
    pub created_ns: u64,
    /// Robots with nodes in it.
    pub robots: usize,
    /// Nodes (each a pose and a leveled scan).
    pub nodes: usize,
    /// Relative edges of the network when frozen.
    pub edges: u64,
    /// GPS edges of the network when frozen.
    pub gps_edges: u64,
    /// Loop closures among the edges.
    pub loop_closures: u64,
    /// The GPS datum: origin of the map's east-north frame.
    pub datum: Option<Geodetic>,
    /// Where its grid lies.
    pub grid: VersionGrid,
    /// The size of its file (bytes).
    pub file_bytes: usize,
    /// Where it came from, when it was imported.
    pub imported_from: Option<ImportedFrom>,
}

/// A version's grid: cell size, the lower-left corner of cell (0, 0), size in cells.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct VersionGrid {
    /// Cell edge (m).
    pub resolution_m: f64,
    /// The lower-left corner of cell (0, 0) in the map frame (m).
    pub origin_m: [f64; 2],
    /// Cells along x.
    pub width: usize,
    /// Cells along y.
    pub height: usize,
}

/// Where an imported version came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ImportedFrom {
    /// Its fleet in the mapper it was exported from.
    pub fleet: String,
    /// Its number there.
    pub version: u64,
    /// When it was imported here (ns since the Unix epoch).
    pub imported_ns: u64,
}

/// Why a version could not be made or taken.
#[derive(Debug, thiserror::Error)]
pub enum VersionError {
    /// The map's grid cannot be made.
    #[error("the map's grid: {0}")]
    Grid(#[from] slam::GridError),
    /// The file cannot be written or read (too large, damaged, another format).
    #[error("{0}")]
    File(#[from] WireError),
}

/// The fleet's map in `view` frozen at `created_ns`, not numbered yet (0). Its grid is made
/// with the API's defaults, coarser when the map needs more cells than a grid may have.
pub fn freeze(view: &FleetView, created_ns: u64) -> Result<MapVersion, VersionError> {
    let params = slam::GridParams {
        coarsen_to_fit: true,
        ..slam::GridParams::default()
    };
    let grid = view.grid(&params)?;
    let nodes = view
        .nodes
        .iter()
        .zip(&view.poses)
        .map(|(n, pose)| {
            let (bearings_rad, ranges_m) = n.scan.polar();
            VersionNode {
                robot: view.robots[n.robot].id.clone(),
                chain_id: n.chain_id,
                node_seq: n.node_seq,
                stamp_ns: n.stamp_ns,
                pose: *pose,
                bearings_rad,
                ranges_m,
            }
        })
        .collect();
    Ok(MapVersion {
        fleet: view.id.clone(),
        number: 0,
        created_ns,
        datum: view.datum,
        edges: view.edges.len() as u64,
        gps_edges: view.gps.len() as u64,
        loop_closures: view.stats.loop_closures as u64,
        nodes,
        grid,
        imported_from: None,
    })
}

/// A version file taken into `fleet` here, checked: it keeps what it holds and its
/// `created_ns`, and says where it came from.
pub fn import(fleet: &str, file: &[u8], imported_ns: u64) -> Result<MapVersion, VersionError> {
    let mut version = wire::decode_map_version_file(file)?;
    version.imported_from = Some(VersionOrigin {
        fleet: std::mem::replace(&mut version.fleet, fleet.to_owned()),
        number: version.number,
        imported_ns,
    });
    Ok(version)
}

/// What the API lists of a version whose file is `file_bytes` long.
pub fn summary_of(version: &MapVersion, file_bytes: usize) -> VersionSummary {
    let g = &version.grid;
    let robots: BTreeSet<&str> = version.nodes.iter().map(|n| n.robot.as_str()).collect();
    VersionSummary {
        fleet: version.fleet.clone(),
        version: version.number,
        created_ns: version.created_ns,
        robots: robots.len(),
        nodes: version.nodes.len(),
        edges: version.edges,
        gps_edges: version.gps_edges,
        loop_closures: version.loop_closures,
        datum: version.datum.map(|d| d.origin),
        grid: VersionGrid {
            resolution_m: g.resolution_m,
            origin_m: g.origin_m,
            width: g.width,
            height: g.height,
        },
        file_bytes,
        imported_from: version.imported_from.as_ref().map(|o| ImportedFrom {
            fleet: o.fleet.clone(),
            version: o.number,
            imported_ns: o.imported_ns,
        }),
    }
}
