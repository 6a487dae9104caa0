//! Messages the conversion tests start from and edit.

use crate::*;
use leveling::TimedPose;
use leveling::nalgebra::{Isometry3, Vector3};
use leveling::{Beam, ClassCounts, LeveledScan, PointClass};

pub(crate) const STAMP_NS: u64 = 1_700_000_000_123_456_789;

pub(crate) fn header(seq: u64) -> v1::Header {
    v1::Header::new("campus", "rover-1", seq, 0, STAMP_NS + 50_000_000)
}

pub(crate) fn scan() -> LeveledScan {
    let beams = (0..360)
        .map(|i| Beam {
            bearing_rad: (i as f32).to_radians() - std::f32::consts::PI,
            range_m: (i % 7 != 0).then_some(1.5 + i as f32 * 0.1),
            sensor_xy_m: [0.0, 0.0],
            ground_to_m: None,
        })
        .collect();
    LeveledScan {
        stamp_ns: STAMP_NS,
        beams,
    }
}

pub(crate) fn counts() -> ClassCounts {
    ClassCounts {
        invalid: 100,
        ground: 20_000,
        landmark: 5_000,
        overhang: 1_900,
    }
}

pub(crate) fn robot_pose() -> Isometry3<f64> {
    Isometry3::new(
        Vector3::new(12.5, -3.25, 0.75),
        Vector3::new(0.05, -0.02, 1.2),
    )
}

pub(crate) fn node() -> v1::Node {
    let mut gps_header = header(4);
    gps_header.stamp_ns = STAMP_NS - 20_000_000;
    v1::Node {
        header: Some(v1::Header::new(
            "campus",
            "rover-1",
            9,
            STAMP_NS,
            STAMP_NS + 1,
        )),
        node_seq: 7,
        chain_id: 0x5eed,
        held_from_seq: 5,
        scan: Some(leveled_scan_to_wire(&scan(), Some(&counts()), header(9))),
        odometry: Some(odometry_to_wire(
            &TimedPose {
                stamp_ns: STAMP_NS,
                pose: robot_pose(),
            },
            header(9),
        )),
        gps: Some(v1::GpsFix {
            header: Some(gps_header.clone()),
            latitude_deg: 52.3822,
            longitude_deg: 9.7166,
            altitude_m: 60.0,
            position_covariance_m2: vec![0.04, 0.0, 0.0, 0.0, 0.04, 0.0, 0.0, 0.0, 0.25],
            status: v1::FixStatus::RtkFixed.into(),
            satellites: 14,
            antenna_offset_m: Some(v1::Vec3 {
                x: 0.1,
                y: 0.0,
                z: 0.9,
            }),
        }),
        earlier_gps: vec![v1::GpsFix {
            header: Some(v1::Header {
                stamp_ns: STAMP_NS - 1_020_000_000,
                ..gps_header
            }),
            latitude_deg: 52.38219,
            longitude_deg: 9.71659,
            altitude_m: 60.1,
            position_covariance_m2: vec![0.04, 0.0, 0.0, 0.0, 0.04, 0.0, 0.0, 0.0, 0.25],
            status: v1::FixStatus::RtkFixed.into(),
            satellites: 13,
            antenna_offset_m: Some(v1::Vec3 {
                x: -1.1,
                y: 0.05,
                z: 0.9,
            }),
        }],
        odometry_delta_from_previous: Some(v1::Pose2D {
            x_m: 4.9,
            y_m: 0.2,
            yaw_rad: 0.05,
        }),
        scan_origin_in_robot: Some(v1::Pose2D {
            x_m: 0.3,
            y_m: 0.0,
            yaw_rad: 0.0,
        }),
        cloud: Some(cloud_to_wire(&cloud())),
    }
}

/// Four points of three classes, reduced from the valid points of `counts()`.
pub(crate) fn cloud() -> ClassifiedCloud {
    ClassifiedCloud {
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
    }
}

pub(crate) fn wire_cloud(n: &mut v1::Node) -> &mut v1::SegmentedCloud {
    n.cloud.as_mut().unwrap()
}

/// Encodes a node after `edit`, decodes it, and returns the error.
pub(crate) fn rejection(edit: impl FnOnce(&mut v1::Node)) -> WireError {
    let mut n = node();
    edit(&mut n);
    decode_node_message(&n.encode_to_vec()).expect_err("must be rejected")
}

pub(crate) fn wire_scan(n: &mut v1::Node) -> &mut v1::LeveledScan {
    n.scan.as_mut().unwrap()
}
