//! Live odometry and live scans, handled in their Zenoh callbacks: the robot's latest pose for
//! `GET …/robots`, its live feed ([`crate::views::live`]) and, at most [`POSE_EVENT_PERIOD_NS`] apart
//! per robot, a `pose` event in the map frame.

use crate::views::{LiveOdometry, Metrics, Shared};
use runtime::session::now_ns;
use serde_json::json;
use slam::Pose2;

/// Live poses go on the event stream at most 2 Hz per robot (odometry arrives at 10 Hz or
/// more; `GET …/robots` has every one).
pub const POSE_EVENT_PERIOD_NS: u64 = 500_000_000;

/// Takes one odometry sample of a served fleet, or counts why not.
pub fn on_odometry(shared: &Shared, fleets: &[String], key: &str, payload: &[u8]) {
    let metrics = &shared.metrics;
    let Ok(parsed) = wire::parse_robot_key(key) else {
        metrics.reject("odom", "invalid_key");
        return;
    };
    if !fleets.iter().any(|f| f == parsed.fleet) {
        metrics.reject("odom", "unknown_fleet");
        return;
    }
    let input = match wire::odometry_input(payload) {
        Ok(o) => o,
        Err(e) => {
            metrics.reject("odom", e.reason());
            return;
        }
    };
    if input.fleet != parsed.fleet || input.robot != parsed.robot {
        metrics.reject("odom", "key_mismatch");
        return;
    }
    Metrics::bump(&metrics.odometry_received);
    let odometry = Pose2::from_isometry3(&input.pose.pose);
    let stamp_ns = input.pose.stamp_ns;
    // Bounded like the fleets' robots: odometry of robots beyond that many is not kept.
    let cap = fleetmap::MAX_ROBOTS_PER_FLEET * fleets.len();
    let Some((due, previous)) = remember(shared, cap, &input, odometry) else {
        return;
    };
    crate::views::live::on_odometry(
        shared,
        cap,
        (&input.fleet, &input.robot),
        (stamp_ns, odometry),
        previous,
    );
    if !due {
        return;
    }
    let map_pose = shared
        .fleet(&input.fleet)
        .and_then(|view| Some(view.robot(&input.robot)?.live_pose(&odometry)));
    if let Some(map_pose) = map_pose {
        shared.event(&json!({
            "type": "pose",
            "fleet": input.fleet,
            "robot": input.robot,
            "pose": map_pose,
            "stamp_ns": stamp_ns,
        }));
    }
}

/// Keeps the robot's latest odometry, unless `cap` robots are kept already (`None`); whether
/// its `pose` event is due, and the odometry it replaces.
fn remember(
    shared: &Shared,
    cap: usize,
    input: &wire::OdometryInput,
    odometry: Pose2,
) -> Option<(bool, Option<(u64, Pose2)>)> {
    let now = now_ns();
    let stamp_ns = input.pose.stamp_ns;
    let mut live = shared.live.lock().expect("live lock");
    let key = (input.fleet.clone(), input.robot.clone());
    if !live.contains_key(&key) && live.len() >= cap {
        shared.metrics.reject("odom", "too_many_robots");
        return None;
    }
    let previous = live.get(&key).map(|p| (p.stamp_ns, p.odometry));
    let last_event = live.get(&key).map_or(0, |p| p.evented_ns);
    let due = now.saturating_sub(last_event) >= POSE_EVENT_PERIOD_NS;
    live.insert(
        key,
        LiveOdometry {
            odometry,
            stamp_ns,
            received_ns: now,
            evented_ns: if due { now } else { last_event },
        },
    );
    Some((due, previous))
}

/// Takes one live scan of a served fleet into its robot's feed, or counts why not.
pub fn on_live_scan(shared: &Shared, fleets: &[String], key: &str, payload: &[u8]) {
    let metrics = &shared.metrics;
    let Ok(parsed) = wire::parse_robot_key(key) else {
        metrics.reject("scan", "invalid_key");
        return;
    };
    if !fleets.iter().any(|f| f == parsed.fleet) {
        metrics.reject("scan", "unknown_fleet");
        return;
    }
    let input = match wire::decode_live_scan(payload) {
        Ok(s) => s,
        Err(e) => {
            metrics.reject("scan", e.reason());
            return;
        }
    };
    if input.fleet != parsed.fleet || input.robot != parsed.robot {
        metrics.reject("scan", "key_mismatch");
        return;
    }
    let cap = fleetmap::MAX_ROBOTS_PER_FLEET * fleets.len();
    if !crate::views::live::on_scan(shared, cap, &input) {
        metrics.reject("scan", "too_many_robots");
    }
}
