use super::*;
use foxglove::messages::{FrameTransforms, LaserScan, LocationFix, PointCloud};
use leveling::{Beam, LeveledScan, PointClass, TimedPose};
use slam::geodesy::Geodetic;
use slam::gnss::{FixStatus, GpsFix};
use slam::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use wire::{ClassifiedCloud, MapPose, Message, NodeParts};

fn node(seq: u64, odometry: Pose2) -> Vec<u8> {
    let pose = Isometry3::from_parts(
        Translation3::new(odometry.x, odometry.y, 0.0),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), odometry.theta),
    );
    let beams = (0..4)
        .map(|k| Beam {
            bearing_rad: -std::f32::consts::PI + k as f32 * std::f32::consts::FRAC_PI_2,
            range_m: Some(2.0 + k as f32),
            sensor_xy_m: [0.0, 0.0],
            ground_to_m: None,
        })
        .collect();
    let parts = NodeParts {
        fleet: "park".into(),
        robot: "r1".into(),
        node_seq: seq,
        chain_id: 7,
        held_from_seq: 0,
        stamp_ns: 1_000_000_000 + seq,
        scan: LeveledScan {
            stamp_ns: 1_000_000_000 + seq,
            beams,
        },
        counts: None,
        odometry: TimedPose {
            stamp_ns: 1_000_000_000 + seq,
            pose,
        },
        odometry_delta: None,
        scan_origin: Pose2::new(0.5, 0.0, 0.0),
        gps: vec![GpsFix {
            stamp_ns: 999_000_000,
            position: Geodetic {
                latitude_deg: 48.0,
                longitude_deg: 7.8,
                height_m: 250.0,
            },
            covariance_m2: None,
            status: FixStatus::RtkFixed,
            antenna_offset_m: Vector3::zeros(),
        }],
        cloud: Some(ClassifiedCloud {
            points_m: vec![[1.0, 2.0, 0.5]],
            classes: vec![PointClass::Landmark],
            source_points: 10,
            voxel_m: 0.0,
            max_points: 0,
        }),
    };
    wire::Node::new(parts).expect("a valid node").encode()
}

#[test]
fn a_node_makes_its_scan_cloud_and_fix_at_its_scan_frame_in_the_odometry_frame() {
    let mut traffic = Traffic::default();
    let key = "levelmap/park/robots/r1/node";
    let out = traffic
        .translate(key, &node(3, Pose2::new(1.0, 2.0, 0.0)), 5)
        .unwrap();
    let topics: Vec<_> = out.iter().map(|m| m.topic.as_str()).collect();
    assert_eq!(
        topics,
        [
            "/park/robots/r1/scan",
            "/park/robots/r1/cloud",
            "/park/robots/r1/gps"
        ]
    );
    assert_eq!(out[0].schema_name, "foxglove.LaserScan");
    assert_eq!(out[0].schema_encoding, "protobuf");
    let scan = LaserScan::decode(&out[0].data[..]).unwrap();
    assert_eq!(scan.frame_id, "park/r1/odom");
    assert_eq!(scan.ranges, [2.0, 3.0, 4.0, 5.0]);
    // The scan frame: the robot's odometry pose, then the scan origin.
    let at = scan.pose.unwrap().position.unwrap();
    assert!((at.x - 1.5).abs() < 1e-9 && (at.y - 2.0).abs() < 1e-9);
    let cloud = PointCloud::decode(&out[1].data[..]).unwrap();
    assert_eq!(
        (cloud.frame_id.as_str(), cloud.data.len()),
        ("park/r1/odom", 13)
    );
    let fix = LocationFix::decode(&out[2].data[..]).unwrap();
    assert_eq!(
        (fix.latitude, fix.longitude, out[2].stamp_ns),
        (48.0, 7.8, 999_000_000)
    );
    assert_eq!(out[0].stamp_ns, 1_000_000_003);
}

#[test]
fn a_solve_places_each_robots_odometry_frame_on_the_map_through_its_named_node() {
    let mut traffic = Traffic::default();
    let key = "levelmap/park/robots/r1/node";
    traffic
        .translate(key, &node(3, Pose2::new(1.0, 2.0, 0.0)), 5)
        .unwrap();
    // The solve puts node 3's scan frame (odometry (1.5, 2)) at (11.5, 2) turned a quarter.
    let at = Pose2::new(11.5, 2.0, std::f64::consts::FRAC_PI_2);
    let poses = [
        MapPose {
            robot: "r1".into(),
            node_seq: 3,
            pose: at,
        },
        // A node the recording never had: no transform.
        MapPose {
            robot: "r2".into(),
            node_seq: 0,
            pose: at,
        },
    ];
    let put = wire::map_poses_to_wire("park", &poses, 9).encode_to_vec();
    let out = traffic
        .translate("levelmap/park/map/poses", &put, 42)
        .unwrap();
    assert_eq!(out.len(), 1);
    assert_eq!((out[0].topic.as_str(), out[0].stamp_ns), ("/tf", 42));
    let tf = FrameTransforms::decode(&out[0].data[..]).unwrap();
    assert_eq!(tf.transforms.len(), 1);
    let t = &tf.transforms[0];
    assert_eq!(
        (t.parent_frame_id.as_str(), t.child_frame_id.as_str()),
        ("park/map", "park/r1/odom")
    );
    // map→odom composed with odom→scan frame gives the solved pose.
    let q = t.rotation.as_ref().unwrap();
    let map_to_odom = Pose2::new(
        t.translation.as_ref().unwrap().x,
        t.translation.as_ref().unwrap().y,
        2.0 * q.z.atan2(q.w),
    );
    let back = map_to_odom.compose(&Pose2::new(1.5, 2.0, 0.0));
    assert!((back.x - at.x).abs() < 1e-9 && (back.y - at.y).abs() < 1e-9);
    assert!((back.theta - at.theta).abs() < 1e-9);
}

#[test]
fn odometry_moves_the_robot_in_its_odometry_frame_and_acks_make_nothing() {
    let mut traffic = Traffic::default();
    let pose = TimedPose {
        stamp_ns: 77,
        pose: Isometry3::translation(3.0, 4.0, 0.0),
    };
    let bytes = wire::encode_odometry("park", "r1", &pose, 1, 78);
    let out = traffic
        .translate("levelmap/park/robots/r1/odom", &bytes, 80)
        .unwrap();
    let tf = FrameTransforms::decode(&out[0].data[..]).unwrap();
    let t = &tf.transforms[0];
    assert_eq!(
        (t.parent_frame_id.as_str(), t.child_frame_id.as_str()),
        ("park/r1/odom", "park/r1")
    );
    assert_eq!(
        (t.translation.as_ref().unwrap().x, out[0].stamp_ns),
        (3.0, 77)
    );
    assert!(
        traffic
            .translate("levelmap/park/robots/r1/ack", b"", 1)
            .unwrap()
            .is_empty()
    );
    assert!(traffic.translate("elsewhere/x", b"", 1).unwrap().is_empty());
    assert!(
        traffic
            .translate("levelmap/park/robots/r1/node", b"\xff", 1)
            .is_err()
    );
}
