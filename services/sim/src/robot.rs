//! Ground-truth motion: a robot driving a route over the drive surface.
//!
//! The robot frame is x forward, y left, z up; its origin sits `body_height_m` above the
//! surface point under the robot's centre. Time is nanoseconds since the route's start.

use crate::world::World;
use nalgebra::{
    Isometry3, Matrix3, Point2, Rotation3, Translation3, UnitQuaternion, Vector2, Vector3,
};

/// Chassis dimensions that set how the robot sits on uneven ground.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobotBody {
    /// Distance between front and rear axle (m): pitch is the slope over this base.
    pub wheelbase_m: f64,
    /// Distance between left and right wheels (m): roll is the slope over this base.
    pub track_m: f64,
    /// Height of the robot frame's origin above the drive surface (m).
    pub body_height_m: f64,
}

impl Default for RobotBody {
    fn default() -> Self {
        RobotBody {
            wheelbase_m: 0.8,
            track_m: 0.6,
            body_height_m: 0.3,
        }
    }
}

impl RobotBody {
    /// The robot's pose standing at (x, y) with heading `yaw_rad`: on the drive surface,
    /// roll and pitch from the surface heights under its wheels.
    pub fn pose_on(&self, world: &World, x: f64, y: f64, yaw_rad: f64) -> Isometry3<f64> {
        let h = |p: Vector2<f64>| world.drive_surface_height_m(x + p.x, y + p.y);
        let forward = Vector2::new(yaw_rad.cos(), yaw_rad.sin());
        let left = Vector2::new(-forward.y, forward.x);
        let (f, b) = (
            forward * (0.5 * self.wheelbase_m),
            -forward * (0.5 * self.wheelbase_m),
        );
        let (l, r) = (left * (0.5 * self.track_m), -left * (0.5 * self.track_m));
        let x_axis = Vector3::new(
            forward.x * self.wheelbase_m,
            forward.y * self.wheelbase_m,
            h(f) - h(b),
        )
        .normalize();
        let y_rough = Vector3::new(left.x * self.track_m, left.y * self.track_m, h(l) - h(r));
        let z_axis = x_axis.cross(&y_rough).normalize();
        let y_axis = z_axis.cross(&x_axis);
        let rotation =
            Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x_axis, y_axis, z_axis]));
        Isometry3::from_parts(
            Translation3::new(
                x,
                y,
                world.drive_surface_height_m(x, y) + self.body_height_m,
            ),
            UnitQuaternion::from_rotation_matrix(&rotation),
        )
    }
}

/// One piece of a route: a straight leg or a circular corner arc.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Piece {
    Line {
        from: Point2<f64>,
        dir: Vector2<f64>,
        length: f64,
    },
    Arc {
        center: Point2<f64>,
        radius: f64,
        /// Angle of the start point seen from the centre (rad).
        start_angle: f64,
        /// +1 counter-clockwise (left turn), −1 clockwise.
        turn: f64,
        length: f64,
    },
}

impl Piece {
    fn length(&self) -> f64 {
        match self {
            Piece::Line { length, .. } | Piece::Arc { length, .. } => *length,
        }
    }

    /// Position and heading at arc length `s` into the piece.
    fn at(&self, s: f64) -> (Point2<f64>, f64) {
        match *self {
            Piece::Line { from, dir, .. } => (from + dir * s, dir.y.atan2(dir.x)),
            Piece::Arc {
                center,
                radius,
                start_angle,
                turn,
                ..
            } => {
                let a = start_angle + turn * s / radius;
                let p = center + Vector2::new(a.cos(), a.sin()) * radius;
                (p, a + turn * std::f64::consts::FRAC_PI_2)
            }
        }
    }
}

/// A path through waypoints with rounded corners, driven at constant speed.
#[derive(Clone, Debug, PartialEq)]
pub struct Route {
    waypoints: Vec<Point2<f64>>,
    closed: bool,
    speed_mps: f64,
    corner_radius_m: f64,
    body: RobotBody,
    pieces: Vec<Piece>,
    /// Arc length at the start of each piece (m).
    starts: Vec<f64>,
    length_m: f64,
    /// Where the robot is at time 0 (arc length, m).
    start_m: f64,
}

/// Default driving speed (m/s): walking pace.
pub const DEFAULT_SPEED_MPS: f64 = 1.4;
/// Default corner radius (m).
pub const DEFAULT_CORNER_RADIUS_M: f64 = 4.0;

impl Route {
    /// An open route from the first waypoint to the last (the robot then stands there).
    /// `None` with fewer than two waypoints, repeated consecutive waypoints, corners that do
    /// not fit their legs, or a negative or non-finite speed (zero is allowed: a robot
    /// standing at the first waypoint, facing the second).
    pub fn open(waypoints: Vec<Point2<f64>>, speed_mps: f64) -> Option<Route> {
        Route::build(waypoints, false, speed_mps, DEFAULT_CORNER_RADIUS_M)
    }

    /// A closed loop through the waypoints, driven round and round. It starts where the
    /// corner at the first waypoint ends, heading for the second waypoint.
    pub fn closed(waypoints: Vec<Point2<f64>>, speed_mps: f64) -> Option<Route> {
        Route::build(waypoints, true, speed_mps, DEFAULT_CORNER_RADIUS_M)
    }

    /// Loop `index` (0, 1 or 2) of the park's footpaths at the default speed: 0 crosses the
    /// bridge, 1 passes the foot of the pavilion hill and runs through the dell, 2 links the
    /// north, the hill's west side and the middle. They overlap in the middle of the park.
    /// (The same loops as [`crate::Places::loops`] of [`World::park`].)
    pub fn park_loop(index: usize) -> Option<Route> {
        let waypoints = crate::park::park_loops().into_iter().nth(index)?;
        Route::closed(waypoints, DEFAULT_SPEED_MPS)
    }

    /// The same route with another chassis.
    pub fn with_body(mut self, body: RobotBody) -> Route {
        self.body = body;
        self
    }

    /// The same route with another corner radius (m), if the corners still fit.
    pub fn with_corner_radius(self, corner_radius_m: f64) -> Option<Route> {
        let start_m = self.start_m;
        Route::build(self.waypoints, self.closed, self.speed_mps, corner_radius_m)
            .map(|r| r.with_body(self.body).starting_at(start_m))
    }

    /// The same route with the robot `start_m` along it at time 0 (wrapped on a loop,
    /// clamped on an open route, as [`Route::point_at`]).
    pub fn starting_at(mut self, start_m: f64) -> Route {
        self.start_m = start_m;
        self
    }

    fn build(
        waypoints: Vec<Point2<f64>>,
        closed: bool,
        speed_mps: f64,
        corner_radius_m: f64,
    ) -> Option<Route> {
        let n = waypoints.len();
        let valid = n >= 2
            && (!closed || n >= 3)
            && speed_mps.is_finite()
            && speed_mps >= 0.0
            && corner_radius_m.is_finite()
            && corner_radius_m >= 0.0
            && waypoints.iter().all(|p| p.x.is_finite() && p.y.is_finite());
        if !valid {
            return None;
        }
        let legs = if closed { n } else { n - 1 };
        let leg = |i: usize| (waypoints[i], waypoints[(i + 1) % n]);
        if (0..legs).any(|i| {
            let (a, b) = leg(i);
            (b - a).norm() < 1e-6
        }) {
            return None;
        }
        // Corner at waypoint i joins leg i−1 and leg i; its tangent length eats into both.
        let corner = |i: usize| -> Option<(f64, f64, f64)> {
            let (a, b) = leg((i + legs - 1) % legs);
            let (_, c) = leg(i);
            let (d_in, d_out) = ((b - a).normalize(), (c - b).normalize());
            let turn = d_in.x * d_out.y - d_in.y * d_out.x;
            let angle = turn.atan2(d_in.dot(&d_out));
            if angle.abs() < 1e-9 {
                return Some((0.0, 0.0, 0.0));
            }
            let tangent = corner_radius_m * (0.5 * angle.abs()).tan();
            Some((tangent, angle, corner_radius_m))
        };
        let has_corner = |i: usize| closed || (i > 0 && i < n - 1);
        let corners: Vec<(f64, f64, f64)> = (0..n)
            .map(|i| {
                if has_corner(i) {
                    corner(i)
                } else {
                    Some((0.0, 0.0, 0.0))
                }
            })
            .collect::<Option<_>>()?;
        let mut pieces = Vec::new();
        for i in 0..legs {
            let (a, b) = leg(i);
            let dir = (b - a).normalize();
            let j = (i + 1) % n;
            let (t_start, t_end) = (corners[i].0, corners[j].0);
            let length = (b - a).norm() - t_start - t_end;
            if length < -1e-9 {
                return None; // corners do not fit on this leg
            }
            pieces.push(Piece::Line {
                from: a + dir * t_start,
                dir,
                length: length.max(0.0),
            });
            let (tangent, angle, radius) = corners[j];
            if has_corner(j) && tangent > 0.0 {
                let start = b - dir * tangent;
                let turn = angle.signum();
                let normal = Vector2::new(-dir.y, dir.x) * turn;
                let center = start + normal * radius;
                let d = start - center;
                pieces.push(Piece::Arc {
                    center,
                    radius,
                    start_angle: d.y.atan2(d.x),
                    turn,
                    length: radius * angle.abs(),
                });
            }
        }
        let mut starts = Vec::with_capacity(pieces.len());
        let mut length_m = 0.0;
        for p in &pieces {
            starts.push(length_m);
            length_m += p.length();
        }
        Some(Route {
            waypoints,
            closed,
            speed_mps,
            corner_radius_m,
            body: RobotBody::default(),
            pieces,
            starts,
            length_m,
            start_m: 0.0,
        })
    }

    /// The waypoints the route goes through (m, world x/y).
    pub fn waypoints(&self) -> &[Point2<f64>] {
        &self.waypoints
    }

    /// Whether the route loops back to its first waypoint.
    pub fn is_closed(&self) -> bool {
        self.closed
    }

    /// Driving speed (m/s).
    pub fn speed_mps(&self) -> f64 {
        self.speed_mps
    }

    /// The robot's body: its wheelbase, track and height above the ground.
    pub fn body(&self) -> &RobotBody {
        &self.body
    }

    /// Length of one pass (m).
    pub fn length_m(&self) -> f64 {
        self.length_m
    }

    /// Time of one pass (ns); `None` for a standing robot.
    pub fn lap_ns(&self) -> Option<u64> {
        (self.speed_mps > 0.0).then(|| (self.length_m / self.speed_mps * 1e9) as u64)
    }

    /// Position and heading (rad) at arc length `s` (m): wrapped on a loop, clamped on an
    /// open route.
    pub fn point_at(&self, s: f64) -> (Point2<f64>, f64) {
        let s = if self.closed {
            s.rem_euclid(self.length_m)
        } else {
            s.clamp(0.0, self.length_m)
        };
        let i = self
            .starts
            .partition_point(|&start| start <= s)
            .saturating_sub(1);
        let piece = &self.pieces[i];
        piece.at((s - self.starts[i]).min(piece.length()))
    }

    /// Horizontal position and heading (rad) at time `t_ns` since the route's start.
    pub fn planar_at(&self, t_ns: u64) -> (Point2<f64>, f64) {
        self.point_at(self.start_m + self.speed_mps * t_ns as f64 * 1e-9)
    }

    /// The robot's true pose (robot frame in the world frame) at `t_ns`.
    pub fn pose_at(&self, world: &World, t_ns: u64) -> Isometry3<f64> {
        let (p, yaw) = self.planar_at(t_ns);
        self.body.pose_on(world, p.x, p.y, yaw)
    }

    /// The ground truth as a function of time, as the sensors take it.
    pub fn truth<'a>(&'a self, world: &'a World) -> impl Fn(u64) -> Isometry3<f64> + 'a {
        move |t_ns| self.pose_at(world, t_ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use leveling::heading_rad;

    #[test]
    fn open_route_runs_straight_then_stops() {
        let world = World::park();
        let route = Route::open(
            vec![Point2::new(-13.0, -50.0), Point2::new(-1.0, -50.0)],
            1.5,
        )
        .unwrap();
        assert!((route.length_m() - 12.0).abs() < 1e-9);
        let (p, yaw) = route.planar_at(2_000_000_000);
        assert!((p.x - -10.0).abs() < 1e-9 && yaw.abs() < 1e-12);
        let (end, _) = route.planar_at(100_000_000_000);
        assert!((end.x - -1.0).abs() < 1e-9);
        // On flat ground the robot sits level, body height above the ground.
        let pose = route.pose_at(&world, 1_000_000_000);
        let g = world.ground_height_m(pose.translation.x, pose.translation.y);
        assert!((pose.translation.z - g - 0.3).abs() < 1e-9);
        let (roll, pitch, _) = pose.rotation.euler_angles();
        assert!(roll.abs() < 0.01 && pitch.abs() < 0.01);
        assert!(Route::open(vec![Point2::origin()], 1.0).is_none());
        assert!(Route::open(vec![Point2::origin(), Point2::origin()], 1.0).is_none());
        assert!(Route::open(vec![Point2::origin(), Point2::new(1.0, 0.0)], -1.0).is_none());
    }

    #[test]
    fn loops_are_smooth_closed_and_on_the_surface() {
        let world = World::park();
        for index in 0..3 {
            let route = Route::park_loop(index).unwrap();
            assert!(
                route.length_m() > 150.0,
                "loop {index}: {} m",
                route.length_m()
            );
            let lap = route.lap_ns().unwrap();
            let start = route.pose_at(&world, 0);
            let again = route.pose_at(&world, lap);
            assert!((start.translation.vector - again.translation.vector).norm() < 0.01);
            // Continuous position and heading at 10 Hz.
            let mut prev = start;
            for k in 1..(lap / 100_000_000) {
                let pose = route.pose_at(&world, k * 100_000_000);
                let step = (pose.translation.vector - prev.translation.vector)
                    .xy()
                    .norm();
                assert!(step < 0.141 + 1e-6, "jump {step} m in loop {index}");
                let dyaw = (heading_rad(&pose.rotation) - heading_rad(&prev.rotation)
                    + 3.0 * std::f64::consts::PI)
                    .rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI;
                assert!(
                    dyaw.abs() < 0.14 * 1.01 / 4.0 + 1e-9,
                    "yaw rate in loop {index}"
                );
                let (roll, pitch, _) = pose.rotation.euler_angles();
                assert!(
                    roll.abs() < 0.5 && pitch.abs() < 0.5,
                    "tilt in loop {index}"
                );
                prev = pose;
            }
        }
        assert!(Route::park_loop(3).is_none());
    }

    #[test]
    fn loops_stay_clear_of_obstacles_and_one_crosses_the_bridge() {
        use crate::world::SurfaceKind;
        let world = World::park();
        let bridge = world.bridge();
        let mut crossings = 0;
        for index in 0..3 {
            let route = Route::park_loop(index).unwrap();
            let mut on_bridge = false;
            let steps = (route.length_m() / 0.25) as usize;
            for k in 0..steps {
                let (p, _) = route.point_at(k as f64 * 0.25);
                on_bridge |= bridge.deck_height_m(p.x, p.y).is_some();
                for part in world.parts() {
                    if part.kind == SurfaceKind::BridgeDeck {
                        continue;
                    }
                    let (lo, hi) = part.shape.z_range_m();
                    let g = world.drive_surface_height_m(p.x, p.y);
                    // Only what the body (up to 1.5 m) could touch; crowns hang higher.
                    if lo > g + 1.5 || hi < g + 0.05 {
                        continue;
                    }
                    let d = part.shape.footprint_distance_m(&p);
                    assert!(
                        d > 0.5,
                        "loop {index} passes {:?} {} at {d:.2} m, at {p}",
                        part.kind,
                        part.object
                    );
                }
            }
            crossings += on_bridge as usize;
        }
        assert!(crossings >= 1);
    }

    #[test]
    fn climbing_pitches_the_nose_up_and_a_side_slope_rolls() {
        let world = World::park();
        let hill = world.pavilion_center();
        let body = RobotBody::default();
        // 10 m east of the hill top, facing it (west): uphill.
        let up = body.pose_on(&world, hill.x + 10.0, hill.y, std::f64::consts::PI);
        let x_axis = up.rotation * Vector3::x();
        assert!(x_axis.z > 0.1, "nose should point up: {x_axis}");
        // Facing north there: the hill is on the left, the left side is higher.
        let side = body.pose_on(&world, hill.x + 10.0, hill.y, std::f64::consts::FRAC_PI_2);
        let y_axis = side.rotation * Vector3::y();
        assert!(y_axis.z > 0.1, "left side should be up: {y_axis}");
    }
}
