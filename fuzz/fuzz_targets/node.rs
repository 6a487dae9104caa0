//! The bytes of a Zenoh node message, as the mapper's worker takes them: the decode and check
//! (`wire::decode_node_input`), then what the mapper does with a node that passes, short of
//! its store and bus (`fleetmap/src/fleet.rs`, `FleetMap::ingest`; `store::split_cloud` and the
//! replay; the cloud served over HTTP). The same bytes also go through the other decoders a
//! service runs on bus messages: acks (edge), live odometry (mapper), map poses and summaries.
#![no_main]

use libfuzzer_sys::fuzz_target;
use slam::geodesy::GeoDatum;
use slam::matching::Scan2;
use slam::{GpsObservation, Mapper2d, Mapper2dParams, Pose2};
use wire::{Message, NodeInput, v1};

/// The mapper's default `max_range_m` (deploy/mapper.toml).
const MAX_RANGE_M: f32 = 40.0;

fuzz_target!(|data: &[u8]| {
    if let Ok((input, node)) = wire::decode_node_input(data) {
        stored_and_replayed(&input, node);
        mapped(&input);
    }
    let _ = wire::decode_ack(data);
    let _ = wire::odometry_input(data);
    let _ = wire::decode_map_poses(data);
    let _ = wire::decode_map_summary(data);
});

/// The mapper stores a node without its cloud and replays it at start through the same
/// check: what passed once must pass again, as the same input. The cloud, stored apart, is
/// read back for `GET …/nodes/{node}/cloud`.
fn stored_and_replayed(input: &NodeInput, mut node: v1::Node) {
    if let Some(cloud) = node.cloud.take() {
        let stored = v1::SegmentedCloud::decode(&cloud.encode_to_vec()[..]).expect("re-decodes");
        wire::cloud_from_wire(&stored).expect("a checked cloud converts");
    }
    let (replayed, _) =
        wire::decode_node_input(&node.encode_to_vec()).expect("a stored node replays");
    assert_eq!(&replayed, input, "the replay differs from the node taken");
}

/// `FleetMap::ingest`: the node's frames, its scan, its GPS observations; then the node into
/// a fleet's network twice, the second a metre on, so that its scan is matched (IDC) against
/// itself, and a solve.
fn mapped(input: &NodeInput) {
    let robot_odometry = Pose2::from_isometry3(&input.odometry.pose);
    let scan_frame = robot_odometry.compose(&input.scan_origin);
    let (bearings, ranges): (Vec<f32>, Vec<f32>) = input.scan.returns().unzip();
    let scan = Scan2::from_polar(&bearings, &ranges, MAX_RANGE_M).expect("returns come in pairs");
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
    // The stored record's scan, for the API (`NodeRecord::scan`).
    let (all_bearings, all_ranges) = input.polar();
    let (b, r): (Vec<f32>, Vec<f32>) = all_bearings
        .iter()
        .zip(&all_ranges)
        .filter(|(_, r)| **r > 0.0)
        .map(|(b, r)| (*b, *r))
        .unzip();
    Scan2::from_polar(&b, &r, f32::MAX).expect("returns come in pairs");

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
