//! The bytes of a Zenoh node message, as the mapper's worker takes them: the decode and check
//! (`wire::decode_node`), then what the mapper does with a node that passes, short of its
//! store and bus (`fleetmap/src/fleet.rs`, `FleetMap::ingest`; `wire::split_node_cloud` and
//! the replay; the cloud served over HTTP; the node encoded again, as a robot encodes one).
//! The same bytes also go through the other decoders a service runs on bus messages: acks
//! (edge), live odometry and live scans (mapper), map poses and summaries.
#![no_main]

use libfuzzer_sys::fuzz_target;
use slam::geodesy::GeoDatum;
use slam::{GpsObservation, Mapper2d, Mapper2dParams, Pose2};
use wire::{Message, Node, v1};

/// The mapper's default `max_range_m` (deploy/mapper.toml).
const MAX_RANGE_M: f32 = 40.0;

fuzz_target!(|data: &[u8]| {
    if let Ok(node) = wire::decode_node(data) {
        stored_and_replayed(&node, data);
        wire::decode_node(&node.encode()).expect("a checked node, encoded, is taken");
        mapped(&node);
    }
    let _ = wire::decode_ack(data);
    let _ = wire::odometry_input(data);
    let _ = wire::decode_live_scan(data);
    let _ = wire::decode_map_poses(data);
    let _ = wire::decode_map_summary(data);
});

/// The mapper stores a node without its cloud and replays it at start through the same
/// check: what passed once must pass again, as the same node. The cloud, stored apart, is
/// read back for `GET …/nodes/{node}/cloud`.
fn stored_and_replayed(node: &Node, data: &[u8]) {
    let (stored, cloud) = wire::split_node_cloud(data.to_vec());
    if let Some(cloud) = cloud {
        let stored = v1::SegmentedCloud::decode(&cloud[..]).expect("a stored cloud decodes");
        let converted = wire::cloud_from_wire(&stored).expect("a checked cloud converts");
        assert_eq!(
            node.cloud.as_ref(),
            Some(&converted),
            "the cloud stored apart differs"
        );
    }
    let replayed = wire::decode_node(&stored).expect("a stored node replays");
    let mut taken = node.clone().into_parts();
    taken.cloud = None;
    assert_eq!(
        replayed.into_parts(),
        taken,
        "the replay differs from the node taken"
    );
}

/// `FleetMap::ingest`: the node's frames, its scan, its GPS observations; then the node into
/// a fleet's network twice, the second a metre on, so that its scan is matched (IDC) against
/// itself, and a solve.
fn mapped(input: &Node) {
    let robot_odometry = Pose2::from_isometry3(&input.odometry.pose);
    let scan_frame = robot_odometry.compose(&input.scan_origin);
    let scan = input.matching_scan(MAX_RANGE_M);
    let attitude = input.odometry.pose.rotation;
    let mut datum: Option<GeoDatum> = None;
    let gps: Vec<GpsObservation> = input
        .gps
        .iter()
        .filter(|fix| fix.has_position())
        .filter_map(|fix| {
            let datum = *datum.get_or_insert(GeoDatum {
                origin: fix.position,
            });
            fix.observation(&datum, &attitude, robot_odometry.theta, &input.scan_origin)
        })
        .collect();
    // The stored record's scan, for the API and the grids (`NodeRecord::scan`).
    wire::matching_scan(&input.scan, f32::MAX);

    // `FleetMap::new`'s settings (every node sent is a node, solves when asked) over the
    // default parameters; the mapper's configuration tunes others, in the same code.
    let mut mapper = Mapper2d::new(Mapper2dParams {
        node_distance_m: 0.0,
        node_rotation_rad: 0.0,
        defer_optimization: true,
        ..Mapper2dParams::default()
    });
    let next = scan_frame.compose(&Pose2::new(1.0, 0.0, 0.05));
    for frame in [scan_frame, next] {
        // A graph error is the mapper's to report, not a crash.
        if mapper.add_robot_scan(0, frame, scan.clone(), &gps).is_err() {
            return;
        }
    }
    let _ = mapper.optimize_now();
}
