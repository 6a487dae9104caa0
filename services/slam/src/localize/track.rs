//! A robot followed on a map from node to node: the pose of its last fix carried forward by
//! its odometry since is the next node's prior, in a window that grows with the path
//! driven without a fix. Without a fix (the start, or too long without one) the node is
//! searched for over the whole map.

use super::{Localization, LocalizationMap, LocalizeError, Prior};
use crate::Pose2;
use crate::matching::Scan2;
use serde::{Deserialize, Serialize};

/// How a robot is followed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackParams {
    /// The window around the odometry's prediction, right after a fix (m, in x and in y)…
    pub window_m: f64,
    /// …and in heading (rad)…
    pub window_rad: f64,
    /// …widened by this much per metre driven since the fix (m/m; odometry drifts)…
    pub growth_per_m: f64,
    /// …up to this (m).
    pub max_window_m: f64,
    /// The heading's window widens by this much per metre driven since the fix (rad/m)…
    pub angular_growth_per_m: f64,
    /// …up to this (rad).
    pub max_window_rad: f64,
    /// After this much path without a fix (m) the robot is lost: its next node is searched
    /// for over the whole map.
    pub lost_after_m: f64,
}

impl Default for TrackParams {
    fn default() -> Self {
        TrackParams {
            window_m: 0.6,
            window_rad: 8f64.to_radians(),
            growth_per_m: 0.1,
            max_window_m: 3.0,
            angular_growth_per_m: 0.5f64.to_radians(),
            max_window_rad: 30f64.to_radians(),
            lost_after_m: 10.0,
        }
    }
}

/// Where a node left the robot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum TrackStatus {
    /// Found in the map.
    Localized,
    /// Not found: its pose is the last fix carried forward by odometry.
    DeadReckoned,
    /// Not found, and no fix recent enough to carry forward.
    Lost,
}

/// The outcome of one node.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackStep {
    /// The node's pose in the map frame: found, or carried forward; `None` when lost.
    pub pose: Option<Pose2>,
    /// Which of the three.
    pub status: TrackStatus,
    /// The match, when found.
    pub found: Option<Localization>,
    /// Why not, when not.
    pub error: Option<LocalizeError>,
}

/// One robot's state on the map.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tracker {
    /// The last fix: the node's odometry pose and its map pose.
    fix: Option<(Pose2, Pose2)>,
    /// The last node's odometry pose.
    last_odometry: Option<Pose2>,
    /// Path driven since the fix (m).
    since_fix_m: f64,
}

impl Tracker {
    /// A robot not yet found.
    pub fn new() -> Tracker {
        Tracker::default()
    }

    /// The map pose of a node at `odometry` (the scan frame in the robot's odometry frame),
    /// from its scan.
    pub fn step(
        &mut self,
        map: &LocalizationMap,
        params: &TrackParams,
        odometry: Pose2,
        scan: &Scan2,
    ) -> TrackStep {
        if let Some(last) = self.last_odometry {
            let step = last.between(&odometry);
            self.since_fix_m += step.x.hypot(step.y);
        }
        self.last_odometry = Some(odometry);
        let predicted = self
            .fix
            .filter(|_| self.since_fix_m <= params.lost_after_m)
            .map(|(at, pose)| pose.compose(&at.between(&odometry)));
        let result = match predicted {
            Some(pose) => {
                let path = self.since_fix_m;
                let prior = Prior {
                    pose,
                    linear_m: (params.window_m + params.growth_per_m * path)
                        .min(params.max_window_m),
                    angular_rad: (params.window_rad + params.angular_growth_per_m * path)
                        .min(params.max_window_rad),
                };
                map.search_window(scan, &prior)
            }
            None => map.search_global(scan),
        };
        match result {
            Ok(found) => {
                self.fix = Some((odometry, found.pose));
                self.since_fix_m = 0.0;
                TrackStep {
                    pose: Some(found.pose),
                    status: TrackStatus::Localized,
                    found: Some(found),
                    error: None,
                }
            }
            Err(error) => TrackStep {
                pose: predicted,
                status: match predicted {
                    Some(_) => TrackStatus::DeadReckoned,
                    None => TrackStatus::Lost,
                },
                found: None,
                error: Some(error),
            },
        }
    }
}
