//! The simulated world: terrain plus solid objects, ray casting with ground truth.

use crate::shape::Shape;
use crate::terrain::Terrain;
use nalgebra::{Point2, Point3, Unit, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// What a ray hit: the ground truth of every simulated return.
///
/// The numeric ids ([`SurfaceKind::id`]) are stable and may be stored; serde writes the
/// variant name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[repr(u8)]
pub enum SurfaceKind {
    /// The natural ground (height field). Id 0.
    Terrain = 0,
    /// The bridge deck, top and underside: the robot drives on it. Id 1.
    BridgeDeck = 1,
    /// A tree trunk: vertical cylinder, a landmark. Id 2.
    TreeTrunk = 2,
    /// A tree crown: ellipsoid wider than the trunk, an overhang. Id 3.
    TreeCrown = 3,
    /// Poles and lamp posts (with their lamp heads). Id 4.
    Pole = 4,
    /// Walls (vertical boxes). Id 5.
    Wall = 5,
    /// Parked cars (boxes). Id 6.
    Car = 6,
    /// Bushes (low ellipsoids). Id 7.
    Bush = 7,
    /// The pavilion's pillars. Id 8.
    PavilionPillar = 8,
    /// The pavilion's roof, overhanging its pillars. Id 9.
    PavilionRoof = 9,
    /// The bridge's railing: posts, hand and knee rails and the deck's side beams. Id 10.
    Railing = 10,
}

impl SurfaceKind {
    /// Every kind, in id order.
    pub const ALL: [SurfaceKind; 11] = [
        SurfaceKind::Terrain,
        SurfaceKind::BridgeDeck,
        SurfaceKind::TreeTrunk,
        SurfaceKind::TreeCrown,
        SurfaceKind::Pole,
        SurfaceKind::Wall,
        SurfaceKind::Car,
        SurfaceKind::Bush,
        SurfaceKind::PavilionPillar,
        SurfaceKind::PavilionRoof,
        SurfaceKind::Railing,
    ];

    /// The stable numeric id.
    pub fn id(self) -> u8 {
        self as u8
    }

    /// The kind with numeric id `id`, if any.
    pub fn from_id(id: u8) -> Option<SurfaceKind> {
        SurfaceKind::ALL.get(id as usize).copied()
    }

    /// True for surfaces the robot drives on (terrain and bridge deck): what a segmentation
    /// should call ground.
    pub fn is_ground(self) -> bool {
        matches!(self, SurfaceKind::Terrain | SurfaceKind::BridgeDeck)
    }

    /// A short snake_case name, for legends and logs.
    pub fn name(self) -> &'static str {
        match self {
            SurfaceKind::Terrain => "terrain",
            SurfaceKind::BridgeDeck => "bridge_deck",
            SurfaceKind::TreeTrunk => "tree_trunk",
            SurfaceKind::TreeCrown => "tree_crown",
            SurfaceKind::Pole => "pole",
            SurfaceKind::Wall => "wall",
            SurfaceKind::Car => "car",
            SurfaceKind::Bush => "bush",
            SurfaceKind::PavilionPillar => "pavilion_pillar",
            SurfaceKind::PavilionRoof => "pavilion_roof",
            SurfaceKind::Railing => "railing",
        }
    }
}

/// The first surface along a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance from the ray's origin (m).
    pub range_m: f64,
    /// What was hit (ground truth).
    pub kind: SurfaceKind,
    /// The physical object hit ([`World::TERRAIN_OBJECT`] for the ground); a tree's trunk
    /// and crown share one id.
    pub object: u32,
}

/// One solid of the world with its ground truth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Part {
    /// The solid.
    pub shape: Shape,
    /// What it is (ground truth).
    pub kind: SurfaceKind,
    /// The physical object the part belongs to.
    pub object: u32,
}

/// The drivable bridge: a straight deck (ramp) from `start_m` to `end_m`, the points where
/// its top surface meets the ground on its centre line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bridge {
    /// Start of the deck's centre line, on the ground (m).
    pub start_m: Point3<f64>,
    /// End of the deck's centre line, on the ground (m).
    pub end_m: Point3<f64>,
    /// Width of the drivable deck (m), between the side beams.
    pub width_m: f64,
    /// Thickness of the deck slab (m).
    pub deck_thickness_m: f64,
    /// Height of the hand rail above the deck (m).
    pub railing_height_m: f64,
}

impl Bridge {
    /// Horizontal length (m).
    pub fn length_m(&self) -> f64 {
        (self.end_m.xy() - self.start_m.xy()).norm()
    }

    /// Height gained from start to end (m).
    pub fn climb_m(&self) -> f64 {
        self.end_m.z - self.start_m.z
    }

    /// Unit horizontal direction from start to end.
    pub fn axis(&self) -> Vector2<f64> {
        (self.end_m.xy() - self.start_m.xy()).normalize()
    }

    /// Position along (m from the start) and across (m, left positive) the centre line.
    pub fn local(&self, x: f64, y: f64) -> (f64, f64) {
        let a = self.axis();
        let d = Vector2::new(x - self.start_m.x, y - self.start_m.y);
        (d.dot(&a), a.x * d.y - a.y * d.x)
    }

    /// Height of the deck's top (m) at (x, y), if the point is on the deck.
    pub fn deck_height_m(&self, x: f64, y: f64) -> Option<f64> {
        let (along, across) = self.local(x, y);
        let length = self.length_m();
        ((0.0..=length).contains(&along) && across.abs() <= 0.5 * self.width_m)
            .then(|| self.start_m.z + self.climb_m() * along / length)
    }
}

/// A straight wall given by its centre line on the ground (m, world x/y).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WallLine {
    /// One end of the centre line (m).
    pub a_m: Point2<f64>,
    /// The other end (m).
    pub b_m: Point2<f64>,
    /// Thickness (m).
    pub thickness_m: f64,
}

impl WallLine {
    /// Signed distance of `p` from the wall's infinite centre line (m, left of a→b positive).
    pub fn signed_distance_m(&self, p: &Point2<f64>) -> f64 {
        let u = (self.b_m - self.a_m).normalize();
        let d = p - self.a_m;
        u.x * d.y - u.y * d.x
    }
}

/// Named places of the park, for scenarios and tests.
#[derive(Clone, Debug, PartialEq)]
pub struct Places {
    /// Centre of the pavilion on the hill top (ground height at the centre).
    pub pavilion_center_m: Point3<f64>,
    /// Radius of the circle the pavilion's pillars stand on (m).
    pub pavilion_pillar_circle_m: f64,
    /// Deepest point of the dell.
    pub dell_center_m: Point3<f64>,
    /// The long straight wall in the flat area, for the motion-compensation test.
    pub test_wall: WallLine,
    /// Where the motion test's robot starts, and the point it drives towards (flat ground).
    pub wall_drive_lane_m: [Point2<f64>; 2],
    /// Where the pavilion scan's robot stands, at the foot of the hill facing the pavilion.
    pub pavilion_view_m: Point2<f64>,
    /// Start and end of the demo scan's short drive on the hill side.
    pub demo_lane_m: [Point2<f64>; 2],
    /// The park's three closed footpath loops (waypoints, m).
    pub loops: [Vec<Point2<f64>>; 3],
    /// The park's extent `[x0, y0, x1, y1]` (m).
    pub bounds_m: [f64; 4],
}

/// Coarse 2D grid over the objects' footprints: a ray only tests the parts listed in the
/// cells it crosses.
#[derive(Clone, Debug)]
struct CullGrid {
    origin: [f64; 2],
    cell_m: f64,
    nx: usize,
    ny: usize,
    /// `starts[c]..starts[c + 1]` index `items` for cell `c`.
    starts: Vec<u32>,
    items: Vec<u32>,
}

impl CullGrid {
    fn new(parts: &[Part], cell_m: f64) -> CullGrid {
        let circles: Vec<([f64; 2], f64)> =
            parts.iter().map(|p| p.shape.bounding_circle()).collect();
        let (mut x0, mut y0, mut x1, mut y1) = (0.0f64, 0.0f64, 1.0f64, 1.0f64);
        for (c, r) in &circles {
            x0 = x0.min(c[0] - r);
            y0 = y0.min(c[1] - r);
            x1 = x1.max(c[0] + r);
            y1 = y1.max(c[1] + r);
        }
        let nx = ((x1 - x0) / cell_m).ceil().max(1.0) as usize;
        let ny = ((y1 - y0) / cell_m).ceil().max(1.0) as usize;
        let cell_of =
            |v: f64, o: f64, n: usize| (((v - o) / cell_m).floor().max(0.0) as usize).min(n - 1);
        let mut lists = vec![Vec::new(); nx * ny];
        for (index, (c, r)) in circles.iter().enumerate() {
            for j in cell_of(c[1] - r, y0, ny)..=cell_of(c[1] + r, y0, ny) {
                for i in cell_of(c[0] - r, x0, nx)..=cell_of(c[0] + r, x0, nx) {
                    lists[j * nx + i].push(index as u32);
                }
            }
        }
        let mut starts = Vec::with_capacity(nx * ny + 1);
        let mut items = Vec::new();
        for list in lists {
            starts.push(items.len() as u32);
            items.extend(list);
        }
        starts.push(items.len() as u32);
        CullGrid {
            origin: [x0, y0],
            cell_m,
            nx,
            ny,
            starts,
            items,
        }
    }

    fn cell(&self, index: usize) -> &[u32] {
        &self.items[self.starts[index] as usize..self.starts[index + 1] as usize]
    }

    /// Visits the cells the ray's horizontal track crosses within `[0, t_max]`, in order,
    /// with the ray parameter at which it enters each; stops when `visit` returns false.
    fn walk(
        &self,
        o: &Point3<f64>,
        d: &Vector3<f64>,
        t_max: f64,
        mut visit: impl FnMut(&[u32], f64) -> bool,
    ) {
        let size = [self.nx as f64 * self.cell_m, self.ny as f64 * self.cell_m];
        let (oo, dd) = ([o.x, o.y], [d.x, d.y]);
        let (mut t0, mut t1) = (0.0f64, t_max);
        for a in 0..2 {
            let (lo, hi) = (self.origin[a], self.origin[a] + size[a]);
            if dd[a].abs() < 1e-12 {
                if oo[a] < lo || oo[a] > hi {
                    return;
                }
            } else {
                let (p, q) = ((lo - oo[a]) / dd[a], (hi - oo[a]) / dd[a]);
                t0 = t0.max(p.min(q));
                t1 = t1.min(p.max(q));
            }
        }
        if t0 > t1 {
            return;
        }
        let n = [self.nx as i64, self.ny as i64];
        let mut cell = [0i64; 2];
        let mut next = [f64::INFINITY; 2];
        let mut delta = [f64::INFINITY; 2];
        let mut step = [0i64; 2];
        for a in 0..2 {
            let local = (oo[a] + dd[a] * t0 - self.origin[a]) / self.cell_m;
            cell[a] = (local.floor() as i64).clamp(0, n[a] - 1);
            if dd[a] > 1e-12 {
                step[a] = 1;
                next[a] = (self.origin[a] + (cell[a] + 1) as f64 * self.cell_m - oo[a]) / dd[a];
                delta[a] = self.cell_m / dd[a];
            } else if dd[a] < -1e-12 {
                step[a] = -1;
                next[a] = (self.origin[a] + cell[a] as f64 * self.cell_m - oo[a]) / dd[a];
                delta[a] = -self.cell_m / dd[a];
            }
        }
        let mut t_enter = t0;
        loop {
            let index = cell[1] as usize * self.nx + cell[0] as usize;
            if !visit(self.cell(index), t_enter) {
                return;
            }
            let a = if next[0] < next[1] { 0 } else { 1 };
            t_enter = next[a];
            if t_enter > t1 {
                return;
            }
            cell[a] += step[a];
            if cell[a] < 0 || cell[a] >= n[a] {
                return;
            }
            next[a] += delta[a];
        }
    }
}

/// A static outdoor world: terrain, objects and a bridge, with named places.
#[derive(Clone, Debug)]
pub struct World {
    terrain: Terrain,
    parts: Vec<Part>,
    /// Bounding circle per part (centre x, y, radius; m) for the quick rejection.
    circles: Vec<[f64; 3]>,
    cull: CullGrid,
    bridge: Bridge,
    places: Places,
    object_count: u32,
}

/// Cell size of the culling grid (m).
const CULL_CELL_M: f64 = 4.0;

impl World {
    /// The object id of the ground.
    pub const TERRAIN_OBJECT: u32 = 0;

    /// A world from its parts (object ids `1..object_count`, 0 is the terrain).
    pub(crate) fn new(terrain: Terrain, parts: Vec<Part>, bridge: Bridge, places: Places) -> World {
        let circles = parts
            .iter()
            .map(|p| {
                let (c, r) = p.shape.bounding_circle();
                [c[0], c[1], r]
            })
            .collect();
        let cull = CullGrid::new(&parts, CULL_CELL_M);
        let object_count = parts.iter().map(|p| p.object + 1).max().unwrap_or(1);
        World {
            terrain,
            parts,
            circles,
            cull,
            bridge,
            places,
            object_count,
        }
    }

    /// The ground.
    pub fn terrain(&self) -> &Terrain {
        &self.terrain
    }

    /// Every solid part of the world with its kind and object id.
    pub fn parts(&self) -> &[Part] {
        &self.parts
    }

    /// Number of object ids in use (terrain included).
    pub fn object_count(&self) -> u32 {
        self.object_count
    }

    /// The bridge.
    pub fn bridge(&self) -> &Bridge {
        &self.bridge
    }

    /// Named places: the pavilion, the dell, test lanes, footpath loops, the extent.
    pub fn places(&self) -> &Places {
        &self.places
    }

    /// Centre of the pavilion on the hill top, at ground height.
    pub fn pavilion_center(&self) -> Point3<f64> {
        self.places.pavilion_center_m
    }

    /// Natural ground height at (x, y) (m, world z).
    pub fn ground_height_m(&self, x: f64, y: f64) -> f64 {
        self.terrain.height_m(x, y)
    }

    /// Height of what the wheels stand on at (x, y) (m): the bridge deck where it covers
    /// the point, else the ground. (The robot never drives under the bridge.)
    pub fn drive_surface_height_m(&self, x: f64, y: f64) -> f64 {
        self.bridge
            .deck_height_m(x, y)
            .unwrap_or_else(|| self.terrain.height_m(x, y))
    }

    /// The first surface along the ray from `origin` in direction `dir` within `max_range_m`.
    pub fn raycast(
        &self,
        origin: &Point3<f64>,
        dir: &Unit<Vector3<f64>>,
        max_range_m: f64,
    ) -> Option<Hit> {
        let d = dir.as_ref();
        let ground = self.terrain.bounds_along(origin, d, max_range_m);
        let mut best = max_range_m;
        if d.z < 0.0 {
            // Below the lowest ground on its way the ray has surely met the ground already:
            // nothing farther can be seen.
            best = best.min((origin.z - ground.min_height_m) / -d.z);
        }
        let mut hit = None;
        let dh = d.x.hypot(d.y);
        self.cull.walk(origin, d, max_range_m, |cell, t_enter| {
            if t_enter > best {
                return false;
            }
            for &index in cell {
                let [cx, cy, r] = self.circles[index as usize];
                // Quick rejection: horizontal distance of the circle's centre from the ray's track.
                let (px, py) = (cx - origin.x, cy - origin.y);
                if dh > 1e-9 {
                    let along = (px * d.x + py * d.y) / dh;
                    let across = (px * d.y - py * d.x) / dh;
                    if across.abs() > r || along < -r || along - r > best * dh {
                        continue;
                    }
                } else if px * px + py * py > r * r {
                    continue;
                }
                let part = &self.parts[index as usize];
                if let Some(t) = part.shape.intersect(origin, d, best) {
                    best = t;
                    hit = Some(Hit {
                        range_m: t,
                        kind: part.kind,
                        object: part.object,
                    });
                }
            }
            true
        });
        match self.terrain.raycast_within(origin, d, best, &ground) {
            Some(t) if t < best => Some(Hit {
                range_m: t,
                kind: SurfaceKind::Terrain,
                object: World::TERRAIN_OBJECT,
            }),
            _ => hit,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn surface_kind_ids_are_stable() {
        for (i, kind) in SurfaceKind::ALL.iter().enumerate() {
            assert_eq!(kind.id() as usize, i);
            assert_eq!(SurfaceKind::from_id(i as u8), Some(*kind));
        }
        assert_eq!(SurfaceKind::from_id(11), None);
        assert_eq!(SurfaceKind::Railing.id(), 10);
        assert!(SurfaceKind::BridgeDeck.is_ground() && !SurfaceKind::Wall.is_ground());
        assert_eq!(SurfaceKind::PavilionPillar.name(), "pavilion_pillar");
    }

    #[test]
    fn a_ray_straight_down_lands_on_the_height_field() {
        let world = World::park();
        for (x, y) in [(0.0, 0.0), (-12.0, 12.0), (-40.0, -22.0), (60.0, 30.0)] {
            let origin = Point3::new(x, y, 30.0);
            let hit = world
                .raycast(&origin, &-Vector3::z_axis(), 100.0)
                .expect("the ground is below");
            assert_eq!(hit.kind, SurfaceKind::Terrain, "at {x}, {y}");
            assert_eq!(hit.object, World::TERRAIN_OBJECT);
            let expected = 30.0 - world.ground_height_m(x, y);
            assert!(
                (hit.range_m - expected).abs() < 1e-3,
                "{} vs {expected}",
                hit.range_m
            );
        }
    }

    #[test]
    fn a_ray_into_a_trunk_hits_it_at_the_right_range() {
        let world = World::park();
        let trunks: Vec<_> = world
            .parts()
            .iter()
            .filter_map(|p| match (p.kind, p.shape) {
                (SurfaceKind::TreeTrunk, Shape::Cylinder(c)) => Some((p.object, c)),
                _ => None,
            })
            .collect();
        assert!(trunks.len() > 30, "{} trees", trunks.len());
        for (object, trunk) in trunks.iter().take(10) {
            let [cx, cy] = trunk.center_xy_m;
            // Aim horizontally at the trunk from 3 m away, 1 m above its ground.
            let z = world.ground_height_m(cx, cy) + 1.0;
            let origin = Point3::new(cx - 3.0, cy, z);
            let hit = world
                .raycast(&origin, &Vector3::x_axis(), 40.0)
                .expect("the trunk is in front");
            assert_eq!(hit.kind, SurfaceKind::TreeTrunk);
            assert_eq!(hit.object, *object);
            assert!((hit.range_m - (3.0 - trunk.radius_m)).abs() < 1e-6);
        }
    }

    #[test]
    fn culling_finds_what_brute_force_finds() {
        let world = World::park();
        let mut rng = crate::rng::Rng::new(5);
        for _ in 0..3000 {
            let (x, y) = (rng.range(-70.0, 70.0), rng.range(-55.0, 55.0));
            let origin = Point3::new(x, y, world.ground_height_m(x, y) + 1.2);
            let (az, el) = (rng.range(-3.2, 3.2), rng.range(-0.6, 0.7));
            let dir = Unit::new_normalize(Vector3::new(
                el.cos() * az.cos(),
                el.cos() * az.sin(),
                el.sin(),
            ));
            let brute = world
                .parts()
                .iter()
                .filter_map(|p| p.shape.intersect(&origin, &dir, 40.0).map(|t| (t, p.kind)))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            let hit = world.raycast(&origin, &dir, 40.0);
            if let Some((t, kind)) = brute {
                let terrain = world
                    .terrain()
                    .raycast(&origin, &dir, 40.0)
                    .unwrap_or(f64::INFINITY);
                if t < terrain {
                    let hit = hit.expect("an object is in the way");
                    assert_eq!(hit.kind, kind);
                    assert!((hit.range_m - t).abs() < 1e-9);
                }
            }
        }
    }

    #[test]
    fn bridge_is_24_m_long_and_climbs_2_m() {
        let world = World::park();
        let bridge = world.bridge();
        assert!((bridge.length_m() - 24.0).abs() < 1e-9);
        assert!(
            (bridge.climb_m() - 2.0).abs() < 0.15,
            "climb {}",
            bridge.climb_m()
        );
        // The deck is the drive surface on the bridge, with room below it in the middle.
        let mid = nalgebra::center(&bridge.start_m, &bridge.end_m);
        let deck = world.drive_surface_height_m(mid.x, mid.y);
        assert!((deck - mid.z).abs() < 1e-9);
        assert!(deck - world.ground_height_m(mid.x, mid.y) > 2.5);
        // Looking straight down onto the deck sees the deck.
        let hit = world
            .raycast(
                &Point3::new(mid.x, mid.y, mid.z + 1.0),
                &-Vector3::z_axis(),
                10.0,
            )
            .expect("deck below");
        assert_eq!(hit.kind, SurfaceKind::BridgeDeck);
        assert!((hit.range_m - 1.0).abs() < 1e-6);
        // Along the deck, the ground never rises through it.
        for i in 1..240 {
            let s = i as f64 / 240.0;
            let p = bridge.start_m + (bridge.end_m - bridge.start_m) * s;
            assert!(
                world.ground_height_m(p.x, p.y) < p.z,
                "ground above the deck at {s}"
            );
        }
    }
}
