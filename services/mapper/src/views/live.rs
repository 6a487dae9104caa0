//! Each robot's live feed, for teleoperation (`GET …/robots/{robot}/live`): at every odometry
//! sample the robot's pose in the map (the last solve's correction applied to live odometry),
//! its speed, the age of that correction, and its newest live leveled scan. One
//! `tokio::sync::watch` per robot holds the newest sample only: a slow subscriber skips to it,
//! and nothing queues. Filled in the Zenoh callbacks, with no mapping work.

use crate::views::Shared;
use runtime::session::now_ns;
use serde::Serialize;
use slam::Pose2;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use tokio::sync::watch;
use utoipa::ToSchema;

/// A robot's newest live leveled scan.
#[derive(Clone, Debug, Serialize, ToSchema)]
pub struct LiveScan {
    /// Counts the robot's live scans (the stream sends each one once).
    pub seq: u64,
    /// The scan's start (ns since the Unix epoch).
    pub stamp_ns: u64,
    /// The scan's frame in the robot's frame.
    pub origin_in_robot: Pose2,
    /// The scan's frame in the map, as the first correction since its arrival placed it
    /// (unset until the robot's first node is mapped).
    pub origin_in_map: Option<Pose2>,
    /// The robot's odometry at the scan: places it once a correction comes.
    #[serde(skip)]
    pub odometry: Pose2,
    /// Beam bearings in the scan's frame (rad).
    pub bearing_rad: Vec<f32>,
    /// Beam ranges (m; 0: no return).
    pub range_m: Vec<f32>,
}

/// One sample of a robot's feed.
#[derive(Clone, Debug, Serialize, ToSchema)]
pub struct LiveSample {
    /// The odometry's stamp (ns since the Unix epoch).
    pub stamp_ns: u64,
    /// When the mapper received it.
    pub received_ns: u64,
    /// The robot's map pose (unset before its first node is mapped).
    pub pose: Option<Pose2>,
    /// Its odometry pose.
    pub odometry: Pose2,
    /// Speed over the last two odometry samples (m/s).
    pub speed_m_s: f64,
    /// How old the correction applied is: since the view holding it was made (ms).
    pub correction_age_ms: Option<f64>,
    /// The newest live scan, when the robot sent one.
    #[serde(skip)]
    pub scan: Option<Arc<LiveScan>>,
}

struct Feed {
    tx: watch::Sender<Option<Arc<LiveSample>>>,
    scan: Option<Arc<LiveScan>>,
    scans: u64,
}

/// Every robot's feed, at most `cap` robots.
#[derive(Default)]
pub struct LiveFeeds {
    feeds: Mutex<HashMap<(String, String), Feed>>,
}

impl std::fmt::Debug for LiveFeeds {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.feeds.lock().map(|m| m.len()).unwrap_or(0);
        write!(f, "LiveFeeds({n} robots)")
    }
}

impl LiveFeeds {
    /// A subscription to a robot's feed, if the robot has one.
    pub fn subscribe(
        &self,
        fleet: &str,
        robot: &str,
    ) -> Option<watch::Receiver<Option<Arc<LiveSample>>>> {
        let feeds = self.feeds.lock().expect("feeds lock");
        let feed = feeds.get(&(fleet.to_owned(), robot.to_owned()))?;
        Some(feed.tx.subscribe())
    }

    /// Runs `f` on the robot's feed, made if it is new and fewer than `cap` are kept; `None`
    /// when it would be one too many.
    fn with_feed<T>(
        &self,
        fleet: &str,
        robot: &str,
        cap: usize,
        f: impl FnOnce(&mut Feed) -> T,
    ) -> Option<T> {
        let mut feeds = self.feeds.lock().expect("feeds lock");
        let key = (fleet.to_owned(), robot.to_owned());
        if !feeds.contains_key(&key) && feeds.len() >= cap {
            return None;
        }
        let feed = feeds.entry(key).or_insert_with(|| Feed {
            tx: watch::Sender::new(None),
            scan: None,
            scans: 0,
        });
        Some(f(feed))
    }
}

/// The correction of a robot, and when the view holding it was made.
fn correction(shared: &Shared, fleet: &str, robot: &str) -> Option<(Pose2, u64)> {
    let view = shared.fleet(fleet)?;
    let r = view.robot(robot)?;
    Some((r.map_from_odometry(), view.updated_ns))
}

/// A new odometry sample of a robot (`previous`: the one before, for the speed).
pub fn on_odometry(
    shared: &Shared,
    cap: usize,
    (fleet, robot): (&str, &str),
    (stamp_ns, odometry): (u64, Pose2),
    previous: Option<(u64, Pose2)>,
) -> bool {
    let now = now_ns();
    let corrected = correction(shared, fleet, robot);
    let speed_m_s = match previous {
        Some((t, p)) if stamp_ns > t => {
            let d = p.between(&odometry);
            d.x.hypot(d.y) / ((stamp_ns - t) as f64 * 1e-9)
        }
        _ => 0.0,
    };
    shared
        .live_feeds
        .with_feed(fleet, robot, cap, |feed| {
            // A scan that came before the robot's first node is placed by the first correction.
            if let (Some(scan), Some((c, _))) = (&feed.scan, corrected)
                && scan.origin_in_map.is_none()
            {
                let origin = c.compose(&scan.odometry).compose(&scan.origin_in_robot);
                feed.scan = Some(Arc::new(LiveScan {
                    origin_in_map: Some(origin),
                    ..(**scan).clone()
                }));
            }
            let sample = LiveSample {
                stamp_ns,
                received_ns: now,
                pose: corrected.map(|(c, _)| c.compose(&odometry)),
                odometry,
                speed_m_s,
                correction_age_ms: corrected.map(|(_, t)| now.saturating_sub(t) as f64 * 1e-6),
                scan: feed.scan.clone(),
            };
            feed.tx.send_replace(Some(Arc::new(sample)));
        })
        .is_some()
}

/// A robot's live scan: kept for the next samples of its feed.
pub fn on_scan(shared: &Shared, cap: usize, input: &wire::LiveScan) -> bool {
    let corrected = correction(shared, &input.fleet, &input.robot);
    let odometry = Pose2::from_isometry3(&input.odometry.pose);
    let (bearing_rad, range_m) = input
        .scan
        .beams
        .iter()
        .map(|b| (b.bearing_rad, b.range_m.unwrap_or(0.0)))
        .unzip();
    shared
        .live_feeds
        .with_feed(&input.fleet, &input.robot, cap, |feed| {
            feed.scans += 1;
            feed.scan = Some(Arc::new(LiveScan {
                seq: feed.scans,
                stamp_ns: input.stamp_ns,
                origin_in_robot: input.scan_origin,
                origin_in_map: corrected
                    .map(|(c, _)| c.compose(&odometry).compose(&input.scan_origin)),
                odometry,
                bearing_rad,
                range_m,
            }));
        })
        .is_some()
}

#[cfg(test)]
mod tests {
    use super::*;
    use fleetmap::FleetMap;
    use leveling::{Beam, LeveledScan, TimedPose};
    use slam::nalgebra::{Isometry3, Translation3, UnitQuaternion};

    #[test]
    fn a_scan_before_the_robots_first_node_is_placed_by_the_first_correction() {
        let shared = Shared::new(String::new(), 0);
        let at = Pose2::new(2.0, 1.0, 0.5);
        let scan = wire::LiveScan {
            fleet: "site".into(),
            robot: "r0".into(),
            stamp_ns: 1,
            scan: LeveledScan {
                stamp_ns: 1,
                beams: vec![Beam {
                    bearing_rad: 0.0,
                    range_m: Some(3.0),
                    sensor_xy_m: [0.0, 0.0],
                    ground_to_m: None,
                }],
            },
            counts: None,
            odometry: TimedPose {
                stamp_ns: 1,
                pose: Isometry3::from_parts(
                    Translation3::new(at.x, at.y, 0.0),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, at.theta),
                ),
            },
            scan_origin: Pose2::new(0.3, 0.0, 0.0),
        };
        assert!(on_scan(&shared, 8, &scan));
        let feed = shared.live_feeds.subscribe("site", "r0").expect("a feed");
        // The robot's first node, then its odometry: the view's correction is there now.
        let mut map = FleetMap::new("site", slam::Mapper2dParams::default(), None, 40.0);
        map.ingest(&fleetmap::testing::node("r0", 1, 0, 0, 0.0))
            .expect("the first node");
        shared.publish_map(&map, 0.0);
        assert!(on_odometry(&shared, 8, ("site", "r0"), (2, at), None));
        let sample = feed.borrow().clone().expect("a sample");
        let placed = sample.scan.as_ref().and_then(|s| s.origin_in_map);
        // The first node sits at its odometry: the correction is the identity.
        let expected = at.compose(&scan.scan_origin);
        let got = placed.expect("placed by the first correction");
        assert!(
            (got.x - expected.x).hypot(got.y - expected.y) < 1e-9
                && (got.theta - expected.theta).abs() < 1e-9,
            "{got:?} vs {expected:?}"
        );
    }
}
