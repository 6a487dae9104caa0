//! Map versions in the store: a fleet's map frozen (`fleetmap::versions::freeze`), kept
//! unchanged under a number and served as one file (`wire::encode_map_version_file`).
//!
//! A version is made from the fleet's current view: the worker publishes a view only after
//! its nodes are committed, and makes it in one piece, so the version is a consistent
//! snapshot of what the store holds; freezing it waits on nothing (recording it is a change
//! the worker journals).

use crate::store::VersionRows;
pub use fleetmap::versions::{
    ImportedFrom, VersionError, VersionGrid, VersionSummary, freeze, import, summary_of,
};
use wire::MapVersion;

/// `version` under `number`: its summary, and its rows as the store keeps them.
pub fn numbered(
    mut version: MapVersion,
    number: u64,
) -> Result<(VersionSummary, VersionRows), VersionError> {
    version.number = number;
    let file = wire::encode_map_version_file(&version)?;
    let summary = summary_of(&version, file.len());
    let json = serde_json::to_vec(&summary).expect("a summary serializes");
    let rows = VersionRows {
        file,
        summary: json,
    };
    Ok((summary, rows))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::MapperConfig;
    use crate::store::{AddVersionError, Store};
    use fleetmap::FleetView;
    use leveling::{Beam, LeveledScan, TimedPose};
    use nalgebra::{Isometry3, Translation3};
    use slam::geodesy::Geodetic;
    use std::sync::Arc;
    use wire::{Node, NodeParts};

    /// Stores `version` in its fleet under the next number (unless the fleet keeps `max`
    /// versions already) and returns its summary. The API numbers a version
    /// ([`numbered`]) and the worker journals it; the test stores it straight.
    fn store(
        store: &Store,
        max: usize,
        version: MapVersion,
    ) -> Result<VersionSummary, AddVersionError<VersionError>> {
        let fleet = version.fleet.clone();
        let mut summary = None;
        store.add_version(&fleet, max, |number| {
            let (made, rows) = numbered(version, number)?;
            summary = Some(made);
            Ok(rows)
        })?;
        Ok(summary.expect("made with the rows"))
    }

    /// Node `seq` of robot r0, `seq` m along, its scan a fan of returns.
    fn node(seq: u64) -> Node {
        let stamp_ns = (seq + 1) * 1_000_000_000;
        let beams = (0..90)
            .map(|k| Beam {
                bearing_rad: k as f32 * 0.07,
                range_m: (k % 11 != 0).then_some(5.0 + (k % 7) as f32),
                sensor_xy_m: [0.0, 0.0],
                ground_to_m: None,
            })
            .collect();
        Node::new(NodeParts {
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
            odometry_delta: None,
            scan_origin: slam::Pose2::IDENTITY,
            gps: Vec::new(),
            cloud: None,
        })
        .expect("a valid node")
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
        let mut map = crate::mapping::new_fleet(&config, "park");
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
        assert_eq!(frozen.nodes[1].ranges_m, v.nodes[1].scan.polar().1);
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
