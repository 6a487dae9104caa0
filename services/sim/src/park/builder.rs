//! The park's objects: each kind of object (tree, bush, lamp post, wall, car, pavilion,
//! bridge) built from shapes standing on the terrain.

use super::PAVILION_PILLAR_CIRCLE_M;
use crate::shape::{Cuboid, Ellipsoid, Shape, VerticalCylinder};
use crate::terrain::Terrain;
use crate::world::{Bridge, Part, SurfaceKind, WallLine};
use nalgebra::{Point2, Point3, UnitQuaternion, Vector2, Vector3};

/// Collects parts, hands out object ids and keeps the footprints of what is placed so far.
pub(super) struct Builder {
    pub(super) terrain: Terrain,
    pub(super) parts: Vec<Part>,
    pub(super) next_object: u32,
    /// Footprint circles (centre, radius) of placed objects, to keep new ones apart.
    pub(super) occupied: Vec<(Point2<f64>, f64)>,
}

impl Builder {
    fn object(&mut self) -> u32 {
        let id = self.next_object;
        self.next_object += 1;
        id
    }

    fn add(&mut self, object: u32, kind: SurfaceKind, shape: Shape) {
        self.parts.push(Part {
            shape,
            kind,
            object,
        });
    }

    pub(super) fn ground(&self, x: f64, y: f64) -> f64 {
        self.terrain.height_m(x, y)
    }

    /// Lowest ground within `radius` of (x, y) (m), from a few samples.
    fn lowest_ground(&self, x: f64, y: f64, radius: f64) -> f64 {
        let mut lo = self.ground(x, y);
        for k in 0..8 {
            let a = k as f64 * std::f64::consts::FRAC_PI_4;
            lo = lo.min(self.ground(x + radius * a.cos(), y + radius * a.sin()));
        }
        lo
    }

    pub(super) fn tree(
        &mut self,
        xy: Point2<f64>,
        trunk_r: f64,
        trunk_h: f64,
        crown_r: f64,
        crown_vr: f64,
    ) {
        let id = self.object();
        let g = self.lowest_ground(xy.x, xy.y, trunk_r);
        // The trunk reaches into the crown; the crown's bottom hangs a little below the trunk
        // top, so from the side the crown is an overhang over the trunk.
        self.add(
            id,
            SurfaceKind::TreeTrunk,
            Shape::Cylinder(VerticalCylinder {
                center_xy_m: [xy.x, xy.y],
                radius_m: trunk_r,
                z_min_m: g - 0.3,
                z_max_m: g + trunk_h + 0.3,
            }),
        );
        self.add(
            id,
            SurfaceKind::TreeCrown,
            Shape::Ellipsoid(Ellipsoid {
                center_m: Point3::new(xy.x, xy.y, g + trunk_h + 0.8 * crown_vr),
                radii_m: Vector3::new(crown_r, crown_r, crown_vr),
            }),
        );
        self.occupied.push((xy, crown_r));
    }

    pub(super) fn bush(&mut self, xy: Point2<f64>, r: f64, h: f64) {
        let id = self.object();
        let g = self.lowest_ground(xy.x, xy.y, r);
        self.add(
            id,
            SurfaceKind::Bush,
            Shape::Ellipsoid(Ellipsoid {
                center_m: Point3::new(xy.x, xy.y, g + 0.5 * h - 0.1),
                radii_m: Vector3::new(r, r, 0.5 * h + 0.1),
            }),
        );
        self.occupied.push((xy, r));
    }

    /// A lamp post: a 4 m pole with a globe on top.
    pub(super) fn lamp(&mut self, xy: Point2<f64>) {
        let id = self.object();
        let g = self.ground(xy.x, xy.y);
        self.add(
            id,
            SurfaceKind::Pole,
            Shape::Cylinder(VerticalCylinder {
                center_xy_m: [xy.x, xy.y],
                radius_m: 0.08,
                z_min_m: g - 0.3,
                z_max_m: g + 4.0,
            }),
        );
        self.add(
            id,
            SurfaceKind::Pole,
            Shape::Ellipsoid(Ellipsoid {
                center_m: Point3::new(xy.x, xy.y, g + 4.1),
                radii_m: Vector3::new(0.25, 0.25, 0.2),
            }),
        );
        self.occupied.push((xy, 0.3));
    }

    /// A vertical box standing on the ground along `a`→`b`, `height` above its lowest ground.
    pub(super) fn wall(
        &mut self,
        a: Point2<f64>,
        b: Point2<f64>,
        thickness: f64,
        height: f64,
        kind: SurfaceKind,
    ) -> WallLine {
        let id = self.object();
        let d = b - a;
        let length = d.norm();
        let samples = (length.ceil() as usize).max(1);
        let g = (0..=samples)
            .map(|i| {
                let p = a + d * (i as f64 / samples as f64);
                self.lowest_ground(p.x, p.y, 0.5 * thickness)
            })
            .fold(f64::INFINITY, f64::min);
        let (bottom, top) = (g - 0.3, g + height);
        let mid = nalgebra::center(&a, &b);
        self.add(
            id,
            kind,
            Shape::Cuboid(Cuboid {
                center_m: Point3::new(mid.x, mid.y, 0.5 * (bottom + top)),
                rotation: UnitQuaternion::from_axis_angle(&Vector3::z_axis(), d.y.atan2(d.x)),
                half_extents_m: Vector3::new(0.5 * length, 0.5 * thickness, 0.5 * (top - bottom)),
            }),
        );
        for i in 0..=samples {
            self.occupied
                .push((a + d * (i as f64 / samples as f64), 0.5 * thickness + 0.5));
        }
        WallLine {
            a_m: a,
            b_m: b,
            thickness_m: thickness,
        }
    }

    /// A parked car, 4.5 m × 1.8 m × 1.5 m, heading `yaw`.
    pub(super) fn car(&mut self, xy: Point2<f64>, yaw: f64) {
        let id = self.object();
        let g = self.lowest_ground(xy.x, xy.y, 2.4);
        let top = self.ground(xy.x, xy.y) + 1.5;
        let bottom = g - 0.1;
        self.add(
            id,
            SurfaceKind::Car,
            Shape::Cuboid(Cuboid {
                center_m: Point3::new(xy.x, xy.y, 0.5 * (bottom + top)),
                rotation: UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
                half_extents_m: Vector3::new(2.25, 0.9, 0.5 * (top - bottom)),
            }),
        );
        self.occupied.push((xy, 2.4));
    }

    /// The pavilion: eight round pillars under a flat round roof that overhangs them.
    pub(super) fn pavilion(&mut self, center: Point2<f64>) {
        let g = self.ground(center.x, center.y);
        let (pillar_top, roof_r) = (g + 2.7, 5.0);
        for k in 0..8 {
            let a = (k as f64 + 0.5) * std::f64::consts::FRAC_PI_4;
            let p = center + Vector2::new(a.cos(), a.sin()) * PAVILION_PILLAR_CIRCLE_M;
            let id = self.object();
            let base = self.lowest_ground(p.x, p.y, 0.25);
            self.add(
                id,
                SurfaceKind::PavilionPillar,
                Shape::Cylinder(VerticalCylinder {
                    center_xy_m: [p.x, p.y],
                    radius_m: 0.25,
                    z_min_m: base - 0.3,
                    z_max_m: pillar_top,
                }),
            );
        }
        let id = self.object();
        for (r, lo, hi) in [
            (roof_r, pillar_top, pillar_top + 0.3),
            (3.2, pillar_top + 0.3, pillar_top + 0.9),
        ] {
            self.add(
                id,
                SurfaceKind::PavilionRoof,
                Shape::Cylinder(VerticalCylinder {
                    center_xy_m: [center.x, center.y],
                    radius_m: r,
                    z_min_m: lo,
                    z_max_m: hi,
                }),
            );
        }
        self.occupied.push((center, roof_r));
    }

    /// The bridge: a straight ramp from ground to ground, railings on both sides.
    pub(super) fn bridge(&mut self, start: Point2<f64>, end: Point2<f64>) -> Bridge {
        let bridge = Bridge {
            start_m: Point3::new(start.x, start.y, self.ground(start.x, start.y)),
            end_m: Point3::new(end.x, end.y, self.ground(end.x, end.y)),
            width_m: 3.0,
            deck_thickness_m: 0.4,
            railing_height_m: 1.0,
        };
        let length = bridge.length_m();
        let axis = bridge.axis();
        let left = Vector2::new(-axis.y, axis.x);
        let pitch = (bridge.climb_m() / length).atan();
        // Yaw along the axis, then nose up by the climb (nalgebra: positive pitch is nose down).
        let rotation = UnitQuaternion::from_euler_angles(0.0, -pitch, axis.y.atan2(axis.x));
        let top_mid = nalgebra::center(&bridge.start_m, &bridge.end_m);
        let half_len = 0.5 * length / pitch.cos();
        let t = bridge.deck_thickness_m;
        let w = bridge.width_m;
        let deck = self.object();
        self.add(
            deck,
            SurfaceKind::BridgeDeck,
            Shape::Cuboid(Cuboid {
                center_m: top_mid - rotation * Vector3::new(0.0, 0.0, 0.5 * t),
                rotation,
                half_extents_m: Vector3::new(half_len, 0.5 * w, 0.5 * t),
            }),
        );
        let side_offset = 0.5 * w + 0.075;
        for side in [-1.0, 1.0] {
            // The side beam covers the deck's edge from 0.1 m below it to a 0.15 m kerb.
            let beam = self.object();
            let (lo, hi) = (-t - 0.1, 0.15);
            self.add(
                beam,
                SurfaceKind::Railing,
                Shape::Cuboid(Cuboid {
                    center_m: top_mid
                        + rotation * Vector3::new(0.0, side * side_offset, 0.5 * (lo + hi)),
                    rotation,
                    half_extents_m: Vector3::new(half_len, 0.075, 0.5 * (hi - lo)),
                }),
            );
            let rails = self.object();
            for height in [0.5, bridge.railing_height_m] {
                let mid = top_mid
                    + Vector3::new(
                        side * side_offset * left.x,
                        side * side_offset * left.y,
                        height,
                    );
                self.add(
                    rails,
                    SurfaceKind::Railing,
                    Shape::Cuboid(Cuboid {
                        center_m: mid,
                        rotation,
                        half_extents_m: Vector3::new(half_len, 0.04, 0.04),
                    }),
                );
            }
            let posts = (length / 2.0).round() as usize;
            for k in 0..=posts {
                let along = length * k as f64 / posts as f64;
                let p = start + axis * along + left * (side * side_offset);
                let z = bridge.start_m.z + bridge.climb_m() * along / length;
                let id = self.object();
                self.add(
                    id,
                    SurfaceKind::Railing,
                    Shape::Cylinder(VerticalCylinder {
                        center_xy_m: [p.x, p.y],
                        radius_m: 0.06,
                        z_min_m: z - 0.1,
                        z_max_m: z + bridge.railing_height_m + 0.04,
                    }),
                );
            }
        }
        for k in 0..=8 {
            let p = start + (end - start) * (k as f64 / 8.0);
            self.occupied.push((p, 0.5 * w + 1.0));
        }
        bridge
    }
}
