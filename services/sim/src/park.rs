//! The park: terrain, objects and named places of [`World::park`].
//!
//! Hand-placed features (pavilion hill, dell, bridge, walls, parking) plus trees, bushes and
//! lamp posts scattered by a fixed seed, kept off the footpaths and the test lanes.

mod builder;

use crate::rng::Rng;
use crate::terrain::{Bump, Terrain};
use crate::world::{Bridge, Places, SurfaceKind, World};
use builder::Builder;
use nalgebra::{Point2, Point3, Vector2};

/// Extent of the park `[x0, y0, x1, y1]` (m): 160 m × 120 m around the datum.
const BOUNDS_M: [f64; 4] = [-80.0, -60.0, 80.0, 60.0];
/// The terrain is cached this far beyond the park, so that rays from its edge stay fast.
const TERRAIN_MARGIN_M: f64 = 50.0;
/// Seed of the scattered trees, bushes and lamps: part of the park's definition.
const PARK_SEED: u64 = 0x7061_726B; // "park"

const PAVILION_XY: [f64; 2] = [-20.0, 20.0];
const PAVILION_PILLAR_CIRCLE_M: f64 = 3.5;
const DELL_XY: [f64; 2] = [-48.0, -22.0];
const BRIDGE_START_XY: [f64; 2] = [18.0, 4.0];
const BRIDGE_END_XY: [f64; 2] = [42.0, 4.0];

/// The footpath loops (m). 0 crosses the bridge; 1 passes the foot of the pavilion hill and
/// runs through the dell; 2 links the north, the hill's west side and the middle.
pub(crate) fn park_loops() -> [Vec<Point2<f64>>; 3] {
    let p = |v: &[[f64; 2]]| v.iter().map(|&[x, y]| Point2::new(x, y)).collect();
    [
        p(&[[0.0, 4.0], [55.0, 4.0], [55.0, -28.0], [5.0, -28.0]]),
        p(&[
            [-4.0, 2.0],
            [-6.0, 32.0],
            [-25.0, 40.0],
            [-52.0, 22.0],
            [-60.0, -4.0],
            [-48.0, -22.0],
            [-25.0, -36.0],
            [-8.0, -18.0],
        ]),
        p(&[
            [-30.0, 46.0],
            [22.0, 46.0],
            [22.0, 18.0],
            [8.0, 12.0],
            [-30.0, -2.0],
            [-40.0, 28.0],
        ]),
    ]
}

fn terrain() -> Terrain {
    let bumps = vec![
        // The pavilion hill: 4.5 m high, steepest slope ≈ 19°.
        Bump::round(PAVILION_XY, 4.5, 8.0),
        // The dell: a hollow 2.5 m deep.
        Bump::round(DELL_XY, -2.5, 7.0),
        // The ravine the bridge crosses, running north–south.
        Bump {
            center_m: [30.0, 0.0],
            amplitude_m: -3.0,
            sigma_m: [5.0, 18.0],
            yaw_rad: 0.0,
        },
        // The east hill whose flank lifts the bridge's far end by 2 m.
        Bump::round([58.0, 4.0], 3.75, 15.0),
        // Rolling ground.
        Bump::round([-62.0, 32.0], 1.5, 11.0),
        Bump {
            center_m: [5.0, 40.0],
            amplitude_m: 1.0,
            sigma_m: [14.0, 9.0],
            yaw_rad: 0.0,
        },
        Bump {
            center_m: [-2.0, -12.0],
            amplitude_m: 0.8,
            sigma_m: [9.0, 12.0],
            yaw_rad: 0.5,
        },
        Bump::round([62.0, -42.0], 1.2, 12.0),
        Bump::round([-68.0, -48.0], 1.0, 10.0),
        Bump::round([68.0, 48.0], 1.4, 12.0),
        Bump {
            center_m: [-42.0, 50.0],
            amplitude_m: 0.7,
            sigma_m: [10.0, 8.0],
            yaw_rad: -0.3,
        },
        Bump::round([-72.0, 2.0], 0.9, 9.0),
    ];
    let [x0, y0, x1, y1] = BOUNDS_M;
    let m = TERRAIN_MARGIN_M;
    Terrain::new(bumps, [x0 - m, y0 - m, x1 + m, y1 + m])
}

/// Distance from `p` to the segment `a`–`b` (m).
fn segment_distance(p: &Point2<f64>, a: &Point2<f64>, b: &Point2<f64>) -> f64 {
    let ab = b - a;
    let t = ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0);
    (p - (a + ab * t)).norm()
}

/// Distance from `p` to a closed polyline (m).
fn loop_distance(p: &Point2<f64>, waypoints: &[Point2<f64>]) -> f64 {
    (0..waypoints.len())
        .map(|i| segment_distance(p, &waypoints[i], &waypoints[(i + 1) % waypoints.len()]))
        .fold(f64::INFINITY, f64::min)
}

/// Where scattered objects may not go (footpaths, lanes, the hill top, the test area).
struct KeepOut {
    loops: [Vec<Point2<f64>>; 3],
    lanes: Vec<[Point2<f64>; 2]>,
    pavilion: Point2<f64>,
    bridge: Bridge,
}

impl KeepOut {
    /// True if an object of footprint radius `r` at `p` leaves everything clear.
    fn allows(&self, p: &Point2<f64>, r: f64) -> bool {
        let [x0, y0, x1, y1] = BOUNDS_M;
        let inside = p.x > x0 + 3.0 && p.x < x1 - 3.0 && p.y > y0 + 3.0 && p.y < y1 - 3.0;
        let off_paths = self.loops.iter().all(|l| loop_distance(p, l) > r + 2.0);
        let off_lanes = self
            .lanes
            .iter()
            .all(|[a, b]| segment_distance(p, a, b) > r + 2.5);
        let (along, across) = self.bridge.local(p.x, p.y);
        let off_bridge = !(across.abs() < 8.0 + r && (-8.0..32.0).contains(&along));
        let off_hilltop = (p - self.pavilion).norm() > 9.0 + r;
        // The flat south area belongs to the motion test: only its wall stands there.
        let off_test_area = !(p.x > -25.0 - r && p.x < 30.0 + r && p.y < -30.0 + r);
        inside && off_paths && off_lanes && off_bridge && off_hilltop && off_test_area
    }
}

impl World {
    /// The synthetic park (deterministic; about 160 m × 120 m):
    /// see the crate documentation for its layout.
    pub fn park() -> World {
        let terrain = terrain();
        let mut b = Builder {
            terrain,
            parts: Vec::new(),
            next_object: World::TERRAIN_OBJECT + 1,
            occupied: Vec::new(),
        };
        let pavilion = Point2::from(PAVILION_XY);
        b.pavilion(pavilion);
        let bridge = b.bridge(Point2::from(BRIDGE_START_XY), Point2::from(BRIDGE_END_XY));

        // Walls: the long straight one in the flat south area crosses the motion test lane
        // at 45°; a long garden wall on the north edge; a shed; a low wall in the south-west.
        // 33 m long, 2.5 m high, from (−3.5, −57.5) to (19.5, −34.5).
        let test_wall = b.wall(
            Point2::new(-3.5, -57.5),
            Point2::new(19.5, -34.5),
            0.3,
            2.5,
            SurfaceKind::Wall,
        );
        b.wall(
            Point2::new(-45.0, 55.0),
            Point2::new(25.0, 55.0),
            0.4,
            2.2,
            SurfaceKind::Wall,
        );
        b.wall(
            Point2::new(-70.0, 43.0),
            Point2::new(-62.0, 43.0),
            6.0,
            3.0,
            SurfaceKind::Wall,
        );
        b.wall(
            Point2::new(-70.0, -30.0),
            Point2::new(-58.0, -40.0),
            0.3,
            1.5,
            SurfaceKind::Wall,
        );

        // Parking east of the ravine, cars nose north.
        for x in [38.0, 41.0, 44.0, 50.0, 53.0] {
            b.car(Point2::new(x, 40.0), std::f64::consts::FRAC_PI_2);
        }

        let loops = park_loops();
        let pavilion_view = pavilion
            + Vector2::new((-35f64).to_radians().cos(), (-35f64).to_radians().sin()) * 17.0;
        let demo_dir = Vector2::new(50f64.to_radians().cos(), 50f64.to_radians().sin());
        let demo_lane = [
            Point2::new(-7.0, 17.0),
            Point2::new(-7.0, 17.0) + demo_dir * 5.0,
        ];
        // Heading east towards the wall, which crosses y = −50 at x = 4: it ends 3.5 m from it.
        let wall_drive_lane = [Point2::new(-9.0, -50.0), Point2::new(-1.0, -50.0)];
        let keep_out = KeepOut {
            loops: loops.clone(),
            lanes: vec![
                wall_drive_lane,
                demo_lane,
                // The view from the foot of the hill to the pavilion stays clear.
                [pavilion_view, pavilion],
            ],
            pavilion,
            bridge,
        };
        let free = |b: &Builder, p: &Point2<f64>, r: f64| {
            keep_out.allows(p, r) && b.occupied.iter().all(|(q, s)| (p - q).norm() > r + s + 0.5)
        };

        // Lamp posts 3 m left of the paths, every 20 m.
        for waypoints in &loops {
            for i in 0..waypoints.len() {
                let (a, c) = (waypoints[i], waypoints[(i + 1) % waypoints.len()]);
                let d = (c - a).normalize();
                let left = Vector2::new(-d.y, d.x);
                let mut s = 8.0;
                while s < (c - a).norm() - 6.0 {
                    let p = a + d * s + left * 3.0;
                    let clear_paths = loops.iter().all(|l| loop_distance(&p, l) > 2.5);
                    let (along, across) = bridge.local(p.x, p.y);
                    let clear_bridge = !(across.abs() < 6.0 && (-6.0..30.0).contains(&along));
                    if clear_paths && clear_bridge && free(&b, &p, 0.3) {
                        b.lamp(p);
                    }
                    s += 20.0;
                }
            }
        }

        // Landmarks in the dell.
        let mut rng = Rng::stream(PARK_SEED, 1);
        let dell = Point2::from(DELL_XY);
        let (mut trees, mut bushes, mut tries) = (0, 0, 0);
        while (trees < 3 || bushes < 2) && tries < 2000 {
            tries += 1;
            let a = rng.range(0.0, std::f64::consts::TAU);
            let p = dell + Vector2::new(a.cos(), a.sin()) * rng.range(3.0, 8.0);
            if trees < 3 {
                let crown = rng.range(1.5, 2.5);
                if free(&b, &p, crown) {
                    b.tree(
                        p,
                        rng.range(0.18, 0.3),
                        rng.range(2.2, 3.0),
                        crown,
                        rng.range(1.5, 2.2),
                    );
                    trees += 1;
                }
            } else {
                let r = rng.range(0.6, 1.2);
                if free(&b, &p, r) {
                    b.bush(p, r, rng.range(0.6, 1.1));
                    bushes += 1;
                }
            }
        }
        let pole = dell + Vector2::new(0.0, -5.0);
        if free(&b, &pole, 0.3) {
            b.lamp(pole);
        }

        // Trees and bushes scattered over the rest of the park.
        let [x0, y0, x1, y1] = BOUNDS_M;
        let mut rng = Rng::stream(PARK_SEED, 2);
        let (mut trees, mut tries) = (0, 0);
        while trees < 80 && tries < 20_000 {
            tries += 1;
            let p = Point2::new(rng.range(x0, x1), rng.range(y0, y1));
            let (trunk_r, trunk_h) = (rng.range(0.15, 0.3), rng.range(2.0, 3.0));
            let (crown_r, crown_vr) = (rng.range(1.5, 3.0), rng.range(1.5, 2.5));
            if free(&b, &p, crown_r) {
                b.tree(p, trunk_r, trunk_h, crown_r, crown_vr);
                trees += 1;
            }
        }
        let mut rng = Rng::stream(PARK_SEED, 3);
        let (mut bushes, mut tries) = (0, 0);
        while bushes < 45 && tries < 20_000 {
            tries += 1;
            let p = Point2::new(rng.range(x0, x1), rng.range(y0, y1));
            let (r, h) = (rng.range(0.6, 1.5), rng.range(0.5, 1.2));
            if free(&b, &p, r) {
                b.bush(p, r, h);
                bushes += 1;
            }
        }

        let dell_z = b.ground(dell.x, dell.y);
        let pavilion_z = b.ground(pavilion.x, pavilion.y);
        let places = Places {
            pavilion_center_m: Point3::new(pavilion.x, pavilion.y, pavilion_z),
            pavilion_pillar_circle_m: PAVILION_PILLAR_CIRCLE_M,
            dell_center_m: Point3::new(dell.x, dell.y, dell_z),
            test_wall,
            wall_drive_lane_m: wall_drive_lane,
            pavilion_view_m: pavilion_view,
            demo_lane_m: demo_lane,
            loops,
            bounds_m: BOUNDS_M,
        };
        World::new(b.terrain, b.parts, bridge, places)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn park_is_deterministic_and_furnished() {
        let (a, b) = (World::park(), World::park());
        assert_eq!(a.parts(), b.parts());
        let count = |kind| a.parts().iter().filter(|p| p.kind == kind).count();
        assert_eq!(count(SurfaceKind::PavilionPillar), 8);
        assert!(
            count(SurfaceKind::TreeTrunk) >= 80,
            "trees {}",
            count(SurfaceKind::TreeTrunk)
        );
        assert!(count(SurfaceKind::Bush) >= 45);
        assert!(
            count(SurfaceKind::Pole) >= 10,
            "lamp parts {}",
            count(SurfaceKind::Pole)
        );
        assert_eq!(count(SurfaceKind::Car), 5);
        assert!(count(SurfaceKind::Railing) > 20);
    }

    #[test]
    fn terrain_is_drivable_and_shaped_as_described() {
        let world = World::park();
        let t = world.terrain();
        assert!(t.slope_bound() < 1.0, "slope bound {}", t.slope_bound());
        let mut steepest = 0.0f64;
        for i in 0..160 {
            for j in 0..120 {
                let [gx, gy] = t.gradient(-80.0 + i as f64, -60.0 + j as f64);
                steepest = steepest.max(gx.hypot(gy));
            }
        }
        assert!(
            steepest.atan().to_degrees() < 30.0,
            "steepest {}°",
            steepest.atan().to_degrees()
        );
        let hill = world.pavilion_center();
        assert!((4.0..5.5).contains(&hill.z), "hill {}", hill.z);
        let dell = world.places().dell_center_m;
        assert!((-3.0..-2.0).contains(&dell.z), "dell {}", dell.z);
        // The motion test area is flat.
        for x in [-15.0, -5.0, 5.0, 15.0] {
            for y in [-55.0, -50.0, -45.0, -40.0] {
                let [gx, gy] = t.gradient(x, y);
                assert!(gx.hypot(gy) < 0.02, "slope {} at {x}, {y}", gx.hypot(gy));
            }
        }
    }
}
