//! Writes the seed inputs of the `map_version` target into the folder given (README.md,
//! "Corpora"): version files, and one version's bare message (the target checks both), each
//! written by `wire::encode_map_version_file` and checked to read back. Deterministic.
//!
//!     cargo run --manifest-path fuzz/Cargo.toml --example map_version_seeds -- DIR

use slam::Pose2;
use slam::geodesy::{GeoDatum, Geodetic};
use std::path::Path;
use wire::{MapVersion, Message, VersionNode, VersionOrigin};

/// `nodes` nodes of two robots, `beams` beams each, on a `side` × `side` grid.
fn version(nodes: u64, beams: usize, side: usize) -> MapVersion {
    let node = |i: u64| VersionNode {
        robot: format!("rover-{}", i % 2),
        chain_id: 0x5eed,
        node_seq: i / 2,
        stamp_ns: 1_700_000_000_000_000_000 + i * 1_000_000_000,
        pose: Pose2::new(i as f64 * 1.5, -0.5 * i as f64, 0.1 * i as f64),
        bearings_rad: (0..beams)
            .map(|k| k as f32 * 6.2 / beams as f32 - 3.1)
            .collect(),
        ranges_m: (0..beams)
            .map(|k| {
                if k % 7 == 0 {
                    0.0
                } else {
                    2.0 + k as f32 * 0.1
                }
            })
            .collect(),
    };
    MapVersion {
        fleet: "campus".into(),
        number: 1,
        created_ns: 1_700_000_100_000_000_000,
        datum: Some(GeoDatum {
            origin: Geodetic {
                latitude_deg: 52.39,
                longitude_deg: 9.71,
                height_m: 55.0,
            },
        }),
        edges: nodes.saturating_sub(1),
        gps_edges: nodes,
        loop_closures: 0,
        nodes: (0..nodes).map(node).collect(),
        grid: slam::OccupancyGrid {
            resolution_m: 0.1,
            origin_m: [-1.6, -0.8],
            width: side,
            height: side,
            cells: (0..side * side)
                .map(|c| [-1, 0, 12, 70, 100][c % 5])
                .collect(),
            occupied_percent: 65,
            free_percent: 35,
        },
        imported_from: None,
    }
}

fn main() {
    let dir = std::env::args()
        .nth(1)
        .expect("usage: map_version_seeds DIR (the folder to write the seeds into)");
    let dir = Path::new(&dir);
    std::fs::create_dir_all(dir).expect("seed folder");
    let mut imported = version(3, 8, 4);
    imported.datum = None;
    imported.imported_from = Some(VersionOrigin {
        fleet: "park".into(),
        number: 7,
        imported_ns: 1_700_000_200_000_000_000,
    });
    let files = [
        ("file-1-node", version(1, 4, 2)),
        ("file-4-nodes", version(4, 16, 8)),
        ("file-imported", imported),
    ];
    for (name, v) in &files {
        let file = wire::encode_map_version_file(v).expect("encodes");
        assert_eq!(
            &wire::decode_map_version_file(&file).expect("reads back"),
            v
        );
        std::fs::write(dir.join(name), file).expect("seed written");
    }
    let bare = wire::map_version_to_wire(&version(2, 8, 4)).encode_to_vec();
    std::fs::write(dir.join("message-2-nodes"), bare).expect("seed written");
}
