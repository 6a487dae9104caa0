//! Writes the seed inputs of the `node` target into the folder given (README.md, "Corpora"):
//! nodes built as `services/wire/src/convert/fixtures.rs` builds its test node, through the
//! same public conversions the edge uses, plus an ack, live odometry, map poses and a map
//! summary, which the target decodes too. Deterministic: the same files every run.
//!
//!     cargo run --manifest-path fuzz/Cargo.toml --example node_seeds -- DIR

use leveling::nalgebra::{Isometry3, Vector3};
use leveling::{Beam, ClassCounts, LeveledScan, PointClass, TimedPose};
use slam::Pose2;
use slam::geodesy::Geodetic;
use slam::gnss::{FixStatus, GpsFix};
use slam::nalgebra::Matrix3;
use std::path::Path;
use wire::{ClassifiedCloud, MapPose, Message, v1};

const STAMP_NS: u64 = 1_700_000_000_123_456_789;

fn header(seq: u64, stamp_ns: u64) -> v1::Header {
    v1::Header::new("campus", "rover-1", seq, stamp_ns, stamp_ns + 50_000_000)
}

/// `beams` beams over a full turn, every seventh without return, ranges rising to ~37 m.
fn scan(beams: usize) -> LeveledScan {
    let step = 360.0 / beams as f32;
    LeveledScan {
        stamp_ns: STAMP_NS,
        beams: (0..beams)
            .map(|i| Beam {
                bearing_rad: (i as f32 * step).to_radians() - std::f32::consts::PI,
                range_m: (i % 7 != 0).then_some(1.5 + i as f32 * 36.0 / beams as f32),
            })
            .collect(),
    }
}

fn counts() -> ClassCounts {
    ClassCounts {
        invalid: 100,
        ground: 20_000,
        landmark: 5_000,
        overhang: 1_900,
    }
}

fn odometry() -> v1::Odometry {
    let pose = Isometry3::new(
        Vector3::new(12.5, -3.25, 0.75),
        Vector3::new(0.05, -0.02, 1.2),
    );
    wire::odometry_to_wire(
        &TimedPose {
            stamp_ns: STAMP_NS,
            pose,
        },
        header(9, STAMP_NS),
    )
}

fn fix(stamp_ns: u64, status: FixStatus, covariance: bool) -> v1::GpsFix {
    let fix = GpsFix {
        stamp_ns,
        position: Geodetic {
            latitude_deg: 52.3822,
            longitude_deg: 9.7166,
            height_m: 60.0,
        },
        covariance_m2: covariance.then(|| Matrix3::from_diagonal(&Vector3::new(0.04, 0.04, 0.25))),
        status,
        antenna_offset_m: Vector3::new(0.1, 0.0, 0.9),
    };
    wire::gps_fix_to_wire(&fix, header(4, stamp_ns))
}

fn cloud() -> v1::SegmentedCloud {
    wire::cloud_to_wire(&ClassifiedCloud {
        points_m: vec![
            [1.25, -0.5, -0.75],
            [-12.5, 3.0, 0.25],
            [4.0, 4.0, 2.5],
            [999.99, -999.99, 0.0],
        ],
        classes: vec![
            PointClass::Ground,
            PointClass::Landmark,
            PointClass::Overhang,
            PointClass::Ground,
        ],
        source_points: 26_900,
        voxel_m: 0.1,
        max_points: 6000,
    })
}

/// The fixtures' node: a scan with counts, odometry, a fix and an earlier one, the odometry
/// delta, the scan's origin and a cloud.
fn full_node(beams: usize) -> v1::Node {
    v1::Node {
        header: Some(header(9, STAMP_NS)),
        node_seq: 7,
        chain_id: 0x5eed,
        held_from_seq: 5,
        scan: Some(wire::leveled_scan_to_wire(
            &scan(beams),
            Some(&counts()),
            header(9, STAMP_NS),
        )),
        odometry: Some(odometry()),
        gps: Some(fix(STAMP_NS - 20_000_000, FixStatus::RtkFixed, true)),
        earlier_gps: vec![fix(STAMP_NS - 1_020_000_000, FixStatus::RtkFloat, true)],
        odometry_delta_from_previous: Some(wire::pose2_to_wire(&Pose2::new(4.9, 0.2, 0.05))),
        scan_origin_in_robot: Some(wire::pose2_to_wire(&Pose2::new(0.3, 0.0, 0.0))),
        cloud: Some(cloud()),
    }
}

fn main() {
    let dir = std::env::args()
        .nth(1)
        .expect("usage: node_seeds DIR (the folder to write the seeds into)");
    let dir = Path::new(&dir);
    std::fs::create_dir_all(dir).expect("seed folder");

    // A planar scanner's node: no counts, no cloud, no GPS.
    let mut planar = full_node(24);
    let s = planar.scan.as_mut().expect("scan");
    s.counts = None;
    (planar.gps, planar.earlier_gps, planar.cloud) = (None, Vec::new(), None);
    // A fix without covariance: the status's default sigma.
    let mut default_sigma = full_node(48);
    default_sigma.gps = Some(fix(STAMP_NS - 5, FixStatus::Fix, false));
    default_sigma.earlier_gps.clear();
    let ack = v1::Ack {
        header: Some(header(3, STAMP_NS)),
        acked_node_seq: Some(6),
        chain_id: 0x5eed,
        resend_from: Some(7),
    };
    let poses = wire::map_poses_to_wire(
        "campus",
        &[
            MapPose {
                robot: "rover-1".into(),
                node_seq: 3,
                pose: Pose2::new(1.5, -2.0, 0.25),
            },
            MapPose {
                robot: "rover-2".into(),
                node_seq: 0,
                pose: Pose2::IDENTITY,
            },
        ],
        STAMP_NS,
    );
    let summary = v1::MapSummary {
        version: wire::WIRE_VERSION,
        fleet_id: "campus".into(),
        sent_ns: STAMP_NS,
        robots: 2,
        nodes: 93,
        edges: 156,
        loop_closures: 10,
        inter_robot_closures: 4,
    };
    let seeds: [(&str, Vec<u8>); 8] = [
        ("node-full-360", full_node(360).encode_to_vec()),
        ("node-full-36", full_node(36).encode_to_vec()),
        ("node-planar-24", planar.encode_to_vec()),
        ("node-default-sigma-48", default_sigma.encode_to_vec()),
        ("ack", ack.encode_to_vec()),
        ("odometry", odometry().encode_to_vec()),
        ("map-poses", poses.encode_to_vec()),
        ("map-summary", summary.encode_to_vec()),
    ];
    // Every seed passes its check, so the fuzzer starts past the decoders.
    for (name, bytes) in &seeds {
        let passes = match *name {
            "ack" => wire::decode_ack(bytes).is_ok(),
            "odometry" => wire::odometry_input(bytes).is_ok(),
            "map-poses" => wire::decode_map_poses(bytes).is_ok(),
            "map-summary" => wire::decode_map_summary(bytes).is_ok(),
            _ => wire::decode_node(bytes).is_ok(),
        };
        assert!(passes, "seed {name} is rejected");
        std::fs::write(dir.join(name), bytes).expect("write a seed");
    }
}
