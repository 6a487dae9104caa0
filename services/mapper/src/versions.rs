//! Map versions: a fleet's map frozen as it is at one moment (every node's pose and leveled
//! scan, the GPS datum, the occupancy grid), kept unchanged in the store under a number and
//! served as one file (`wire::encode_map_version_file`). A version is the unit a fleet
//! rolls out; `levelmap map export` and `import` move it between mappers.
//!
//! A version is made from the fleet's current view: the worker publishes a view only after
//! its nodes are committed, and makes it in one piece, so the version is a consistent
//! snapshot of what the store holds, and freezing never waits on the worker.

use crate::store::{AddVersionError, Store, VersionRows};
use fleetmap::FleetView;
use serde::{Deserialize, Serialize};
use slam::geodesy::Geodetic;
use std::collections::BTreeSet;
use utoipa::ToSchema;
use wire::{MapVersion, VersionNode, VersionOrigin, WireError};

/// A version in numbers, as the API lists it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
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
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
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
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
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
        .map(|(n, pose)| VersionNode {
            robot: view.robots[n.robot].id.clone(),
            chain_id: n.chain_id,
            node_seq: n.node_seq,
            stamp_ns: n.stamp_ns,
            pose: *pose,
            bearings_rad: n.bearings_rad.clone(),
            ranges_m: n.ranges_m.clone(),
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

/// Stores `version` in its fleet under the next number (unless the fleet keeps `max`
/// versions already) and returns its summary.
pub fn store(
    store: &Store,
    max: usize,
    mut version: MapVersion,
) -> Result<VersionSummary, AddVersionError<VersionError>> {
    let fleet = version.fleet.clone();
    let mut summary = None;
    store.add_version(&fleet, max, |number| {
        version.number = number;
        let file = wire::encode_map_version_file(&version)?;
        let made = summary_of(&version, file.len());
        let json = serde_json::to_vec(&made).expect("a summary serializes");
        summary = Some(made);
        Ok(VersionRows {
            file,
            summary: json,
        })
    })?;
    Ok(summary.expect("made with the rows"))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::MapperConfig;
    use leveling::{Beam, LeveledScan, TimedPose};
    use nalgebra::{Isometry3, Translation3};
    use std::sync::Arc;
    use wire::NodeInput;

    /// Node `seq` of robot r0, `seq` m along, its scan a fan of returns.
    fn node(seq: u64) -> NodeInput {
        let stamp_ns = (seq + 1) * 1_000_000_000;
        let beams = (0..90)
            .map(|k| Beam {
                bearing_rad: k as f32 * 0.07,
                range_m: (k % 11 != 0).then_some(5.0 + (k % 7) as f32),
            })
            .collect();
        NodeInput {
            fleet: "park".into(),
            robot: "r0".into(),
            node_seq: seq,
            chain_id: 7,
            held_from_seq: 0,
            stamp_ns,
            scan: LeveledScan { stamp_ns, beams },
            counts: None,
            odometry: TimedPose {
                stamp_ns,
                pose: Isometry3::from_parts(
                    Translation3::new(seq as f64, 0.0, 0.0),
                    Default::default(),
                ),
            },
            scan_origin: slam::Pose2::IDENTITY,
            gps: Vec::new(),
        }
    }

    fn view(nodes: u64) -> FleetView {
        let config = MapperConfig {
            datum: Some(Geodetic {
                latitude_deg: 52.39,
                longitude_deg: 9.71,
                height_m: 55.0,
            }),
            ..MapperConfig::default()
        };
        let mut map = config.new_fleet("park");
        for seq in 0..nodes {
            map.ingest(&node(seq)).unwrap();
        }
        FleetView::of(&map, None, 0.0, 1)
    }

    #[test]
    fn a_frozen_view_is_stored_numbered_and_reads_back_unchanged() {
        let v = view(3);
        let frozen = freeze(&v, 42).unwrap();
        assert_eq!(frozen.nodes.len(), 3);
        assert_eq!(frozen.nodes[2].pose, v.poses[2]);
        assert_eq!(frozen.nodes[1].ranges_m, v.nodes[1].ranges_m);
        assert_eq!(frozen.datum, v.datum);
        let path = std::env::temp_dir().join(format!(
            "levelmap-versions-frozen-{}.redb",
            std::process::id()
        ));
        let _ = std::fs::remove_file(&path);
        let db = Arc::new(Store::open(&path).unwrap());
        let summary = store(&db, 2, frozen.clone()).unwrap();
        assert_eq!((summary.version, summary.nodes, summary.robots), (1, 3, 1));
        let file = db.version_file("park", 1).unwrap().unwrap();
        assert_eq!(summary.file_bytes, file.len());
        let stored: VersionSummary =
            serde_json::from_slice(&db.version_summary("park", 1).unwrap().unwrap()).unwrap();
        assert_eq!(stored, summary);
        let back = wire::decode_map_version_file(&file).unwrap();
        assert_eq!(
            back,
            MapVersion {
                number: 1,
                ..frozen.clone()
            }
        );
        // Imported under another fleet: the same map, and where it came from.
        let imported = import("campus", &file, 7).unwrap();
        assert_eq!(
            (imported.nodes.as_slice(), imported.datum),
            (frozen.nodes.as_slice(), frozen.datum)
        );
        assert_eq!(imported.fleet, "campus");
        let summary = store(&db, 2, imported).unwrap();
        assert_eq!(summary.version, 1);
        let from = summary.imported_from.unwrap();
        assert_eq!(
            (from.fleet.as_str(), from.version, from.imported_ns),
            ("park", 1, 7)
        );
        // A cut file is refused; nothing is stored.
        assert!(import("campus", &file[..file.len() - 1], 7).is_err());
        assert_eq!(db.version_summaries("campus").unwrap().len(), 1);
        drop(db);
        std::fs::remove_file(&path).ok();
    }
}
