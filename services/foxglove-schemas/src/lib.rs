//! levelmap's domain types as Foxglove's well-known messages: pure, no I/O, no clock. The
//! live feed beside the mapper (`foxglove-feed`) and `levelmap record --foxglove` write
//! these, in the frames both name alike:
//!
//! | frame | what |
//! |---|---|
//! | `{fleet}/map` | the fleet's map (x east, y north, as the HTTP API's poses) |
//! | `{fleet}/{robot}/odom` | a robot's odometry frame (recordings: the map → odometry transform from each solve) |
//! | `{fleet}/{robot}` | the robot |
//!
//! A node's leveled scan and cloud are placed with their scan frame's planar pose (the
//! node's pose); the leveled frame is level, so a planar pose places it whole.

use foxglove::messages::{
    FrameTransform, Grid, LaserScan, LocationFix, PackedElementField, PointCloud, Pose,
    PoseInFrame, Quaternion, Timestamp, Vector2, Vector3, location_fix, packed_element_field,
};
use leveling::{LeveledScan, PointClass};
use slam::geodesy::{GeoDatum, Geodetic};
use slam::gnss::{GpsFix, GpsObservation};
use slam::{CellState, OccupancyGrid, Pose2};
use std::f64::consts::PI;
use wire::ClassifiedCloud;

pub mod traffic;

#[cfg(test)]
mod tests;

/// A fleet's map frame.
pub fn map_frame(fleet: &str) -> String {
    format!("{fleet}/map")
}

/// A robot's frame.
pub fn robot_frame(fleet: &str, robot: &str) -> String {
    format!("{fleet}/{robot}")
}

/// A robot's odometry frame.
pub fn odom_frame(fleet: &str, robot: &str) -> String {
    format!("{fleet}/{robot}/odom")
}

/// A time in ns since the Unix epoch as Foxglove's.
pub fn timestamp(ns: u64) -> Timestamp {
    let sec = u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX);
    Timestamp::new(sec, (ns % 1_000_000_000) as u32)
}

/// A planar pose as a 3D one (z 0, a rotation about z).
pub fn pose(p: &Pose2) -> Pose {
    Pose {
        position: Some(Vector3 {
            x: p.x,
            y: p.y,
            z: 0.0,
        }),
        orientation: Some(yaw(p.theta)),
    }
}

fn yaw(theta: f64) -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: (theta / 2.0).sin(),
        w: (theta / 2.0).cos(),
    }
}

/// A planar pose in `frame`.
pub fn pose_in_frame(frame: String, p: &Pose2, stamp_ns: u64) -> PoseInFrame {
    PoseInFrame {
        timestamp: Some(timestamp(stamp_ns)),
        frame_id: frame,
        pose: Some(pose(p)),
    }
}

/// The transform from `parent` to `child`, whose pose in `parent` is `p`.
pub fn transform(parent: String, child: String, p: &Pose2, stamp_ns: u64) -> FrameTransform {
    FrameTransform {
        timestamp: Some(timestamp(stamp_ns)),
        parent_frame_id: parent,
        child_frame_id: child,
        translation: Some(Vector3 {
            x: p.x,
            y: p.y,
            z: 0.0,
        }),
        rotation: Some(yaw(p.theta)),
    }
}

/// A field of a packed element (a grid's cell, a cloud's point).
fn field(name: &str, offset: u32, kind: packed_element_field::NumericType) -> PackedElementField {
    let mut field = PackedElementField {
        name: name.into(),
        offset,
        ..Default::default()
    };
    field.set_type(kind);
    field
}

/// The occupancy grid as a `foxglove.Grid` in `frame`, two bytes a cell, row 0 at the grid's
/// origin corner (lowest y): `occupancy` (INT8: −1 never seen, else 0–100 per cent, as
/// `nav_msgs/OccupancyGrid`) and `state` (UINT8: the grid's tri-state as `map.pgm` draws it,
/// light to dark so that a two-colour gradient draws it too: 0 free, 1 unknown, 2 occupied).
pub fn grid(frame: String, g: &OccupancyGrid, stamp_ns: u64) -> Grid {
    use packed_element_field::NumericType::{Int8, Uint8};
    let shade = |c: i8| match g.classify(c) {
        CellState::Free => 0u8,
        CellState::Unknown => 1,
        CellState::Occupied => 2,
    };
    let data: Vec<u8> = g.cells.iter().flat_map(|&c| [c as u8, shade(c)]).collect();
    Grid {
        timestamp: Some(timestamp(stamp_ns)),
        frame_id: frame,
        pose: Some(pose(&Pose2::new(g.origin_m[0], g.origin_m[1], 0.0))),
        column_count: g.width as u32,
        cell_size: Some(Vector2 {
            x: g.resolution_m,
            y: g.resolution_m,
        }),
        row_stride: 2 * g.width as u32,
        cell_stride: 2,
        fields: vec![field("occupancy", 0, Int8), field("state", 1, Uint8)],
        data: data.into(),
    }
}

/// The bearings a laser scan of `beams` beams is drawn on: `(start, step)`. A scan whose
/// bearings cover the turn but for two steps (a spinning sensor) gets the whole turn from −π,
/// else the span of its bearings (a 2D scanner's 180° or 270°).
fn scan_bins(scan: &LeveledScan) -> (f64, f64) {
    let n = scan.beams.len();
    let bearings = scan.beams.iter().map(|b| wrap(f64::from(b.bearing_rad)));
    let (lo, hi) = bearings.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), b| {
        (lo.min(b), hi.max(b))
    });
    if n == 0 {
        return (0.0, 0.0);
    }
    if n == 1 || hi <= lo {
        return (lo, 0.0);
    }
    if hi - lo > 2.0 * PI * (1.0 - 2.0 / n as f64) {
        (-PI, 2.0 * PI / n as f64)
    } else {
        (lo, (hi - lo) / (n - 1) as f64)
    }
}

/// An angle in [−π, π).
fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(2.0 * PI) - PI
}

/// A node's leveled scan as a `foxglove.LaserScan` in `frame`, from the scan frame's pose
/// `origin` there. LaserScan's ranges lie on equally spaced bearings and a leveled scan's
/// need not (a moving sensor's columns), so each return goes to the nearest of as many
/// bearings as the scan has beams ([`scan_bins`]; the nearer return where two meet): a
/// return is off by at most half a step in bearing, never in range. Bearings without a
/// return are NaN, which Foxglove does not draw.
pub fn laser_scan(frame: String, origin: &Pose2, scan: &LeveledScan) -> LaserScan {
    let n = scan.beams.len();
    let (start, step) = scan_bins(scan);
    let full_turn = step > 0.0 && (step * n as f64 - 2.0 * PI).abs() < 1e-9;
    let mut ranges = vec![f64::NAN; n];
    for (bearing, range) in scan.returns() {
        let at = if step > 0.0 {
            (wrap(f64::from(bearing)) - start) / step
        } else {
            0.0
        };
        let i = if full_turn {
            (at.round() as usize) % n
        } else {
            (at.round().max(0.0) as usize).min(n - 1)
        };
        let r = f64::from(range);
        if ranges[i].is_nan() || r < ranges[i] {
            ranges[i] = r;
        }
    }
    LaserScan {
        timestamp: Some(timestamp(scan.stamp_ns)),
        frame_id: frame,
        pose: Some(pose(origin)),
        start_angle: start,
        end_angle: start + step * n.saturating_sub(1) as f64,
        ranges,
        intensities: Vec::new(),
    }
}

/// The bytes of one point of a cloud: x, y, z (f32, m) and its class (u8).
pub const CLOUD_POINT_STRIDE: u32 = 13;

/// A node's segmented cloud as a `foxglove.PointCloud` in `frame`, from its scan frame's
/// pose `origin` there: fields `x`, `y`, `z` (FLOAT32, m, the leveled frame) and `class`
/// (UINT8: 1 ground, 2 landmark, 3 overhang, as the HTTP API's).
pub fn point_cloud(
    frame: String,
    origin: &Pose2,
    cloud: &ClassifiedCloud,
    stamp_ns: u64,
) -> PointCloud {
    use packed_element_field::NumericType::{Float32, Uint8};
    let mut data = Vec::with_capacity(cloud.points_m.len() * CLOUD_POINT_STRIDE as usize);
    for (p, &class) in cloud.points_m.iter().zip(&cloud.classes) {
        if class == PointClass::Invalid {
            continue;
        }
        for v in p {
            data.extend_from_slice(&v.to_le_bytes());
        }
        data.push(class as u8);
    }
    PointCloud {
        timestamp: Some(timestamp(stamp_ns)),
        frame_id: frame,
        pose: Some(pose(origin)),
        point_stride: CLOUD_POINT_STRIDE,
        fields: vec![
            field("x", 0, Float32),
            field("y", 4, Float32),
            field("z", 8, Float32),
            field("class", 12, Uint8),
        ],
        data: data.into(),
    }
}

/// A fix as the receiver gave it, as a `foxglove.LocationFix` in `frame`: its covariance
/// (east-north-up, as LocationFix's) when it has one, else its status's default deviation
/// on every axis (approximated). `None` for a fix without a position.
pub fn location_fix(frame: String, fix: &GpsFix) -> Option<LocationFix> {
    use location_fix::PositionCovarianceType::{Approximated, Known};
    let (covariance, kind) = match fix.covariance_m2 {
        Some(c) => (c.transpose().as_slice().to_vec(), Known),
        None => {
            let var = fix.status.default_sigma_m()?.powi(2);
            (diagonal([var, var, var]), Approximated)
        }
    };
    fix.has_position()
        .then(|| located(frame, &fix.position, covariance, kind, fix.stamp_ns))
}

/// A fix as the mapper took it (an observation east and north of the fleet's datum), as a
/// `foxglove.LocationFix` in `frame`: its horizontal covariance, its height the datum's (an
/// observation keeps none; the up variance is the larger horizontal one, approximated).
pub fn observed_fix(
    frame: String,
    datum: &GeoDatum,
    observation: &GpsObservation,
    stamp_ns: u64,
) -> LocationFix {
    let p = observation.position_m;
    let at = datum.enu_to_geodetic(&slam::nalgebra::Vector3::new(p.x, p.y, 0.0));
    let c = observation.covariance_m2;
    let up = c[(0, 0)].max(c[(1, 1)]);
    let covariance = vec![
        c[(0, 0)],
        c[(0, 1)],
        0.0,
        c[(1, 0)],
        c[(1, 1)],
        0.0,
        0.0,
        0.0,
        up,
    ];
    let kind = location_fix::PositionCovarianceType::Approximated;
    located(frame, &at, covariance, kind, stamp_ns)
}

fn diagonal(v: [f64; 3]) -> Vec<f64> {
    vec![v[0], 0.0, 0.0, 0.0, v[1], 0.0, 0.0, 0.0, v[2]]
}

fn located(
    frame: String,
    at: &Geodetic,
    covariance: Vec<f64>,
    kind: location_fix::PositionCovarianceType,
    stamp_ns: u64,
) -> LocationFix {
    let mut fix = LocationFix {
        timestamp: Some(timestamp(stamp_ns)),
        frame_id: frame,
        latitude: at.latitude_deg,
        longitude: at.longitude_deg,
        altitude: at.height_m,
        position_covariance: covariance,
        ..Default::default()
    };
    fix.set_position_covariance_type(kind);
    fix
}
