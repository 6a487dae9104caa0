//! Solid primitives the park's objects are made of, with analytic ray intersection.
//!
//! All coordinates are world coordinates in metres (x, y horizontal, z up along gravity).
//! A ray is an origin and a unit direction; intersections return the distance along it (m)
//! to the first surface the ray *enters*. A ray that starts inside a solid does not see it.

use nalgebra::{Point2, Point3, UnitQuaternion, Vector3};

/// Rays closer than this (m) to their origin ignore a surface: no self-hits.
const MIN_HIT_M: f64 = 1e-6;

/// An upright circular cylinder (trunks, poles, pillars, flat round roofs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VerticalCylinder {
    /// Axis position (m).
    pub center_xy_m: [f64; 2],
    /// Radius (m).
    pub radius_m: f64,
    /// Bottom and top (m, world z).
    pub z_min_m: f64,
    /// See `z_min_m`.
    pub z_max_m: f64,
}

/// An axis-aligned ellipsoid (tree crowns, bushes, lamp heads).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ellipsoid {
    /// Centre (m, world frame).
    pub center_m: Point3<f64>,
    /// Semi-axes along world x, y, z (m).
    pub radii_m: Vector3<f64>,
}

/// A rotated box (walls, cars, the bridge deck, rails).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cuboid {
    /// Centre (m, world frame).
    pub center_m: Point3<f64>,
    /// Box frame in the world frame.
    pub rotation: UnitQuaternion<f64>,
    /// Half the edge lengths along the box's own x, y, z (m).
    pub half_extents_m: Vector3<f64>,
}

/// One solid primitive.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// An upright cylinder (trunks, poles, pillars).
    Cylinder(VerticalCylinder),
    /// An axis-aligned ellipsoid (crowns, bushes, lamp heads).
    Ellipsoid(Ellipsoid),
    /// A rotated box (walls, cars, the bridge deck, rails).
    Cuboid(Cuboid),
}

/// The parameter interval `[t0, t1]` in which `o + t·d` lies within `[lo, hi]` on one axis.
#[inline]
fn slab(o: f64, d: f64, lo: f64, hi: f64) -> Option<(f64, f64)> {
    if d.abs() < 1e-12 {
        return (lo..=hi)
            .contains(&o)
            .then_some((f64::NEG_INFINITY, f64::INFINITY));
    }
    let inv = 1.0 / d;
    let (a, b) = ((lo - o) * inv, (hi - o) * inv);
    Some(if a <= b { (a, b) } else { (b, a) })
}

/// Entry distance of an interval that the ray enters in front of its origin.
#[inline]
fn entry((t0, t1): (f64, f64), t_max: f64) -> Option<f64> {
    (t0 <= t1 && t0 >= MIN_HIT_M && t0 <= t_max).then_some(t0)
}

/// Interval of `t` where the quadratic `a t² + 2 b t + c` is ≤ 0, for `a > 0`.
#[inline]
fn inside_quadratic(a: f64, b: f64, c: f64) -> Option<(f64, f64)> {
    let disc = b * b - a * c;
    if disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    Some(((-b - s) / a, (-b + s) / a))
}

impl VerticalCylinder {
    fn intersect(&self, o: &Point3<f64>, d: &Vector3<f64>, t_max: f64) -> Option<f64> {
        let (px, py) = (o.x - self.center_xy_m[0], o.y - self.center_xy_m[1]);
        let a = d.x * d.x + d.y * d.y;
        let radial = if a < 1e-18 {
            // Vertical ray: inside the disc or never.
            (px * px + py * py <= self.radius_m * self.radius_m)
                .then_some((f64::NEG_INFINITY, f64::INFINITY))?
        } else {
            inside_quadratic(
                a,
                px * d.x + py * d.y,
                px * px + py * py - self.radius_m * self.radius_m,
            )?
        };
        let axial = slab(o.z, d.z, self.z_min_m, self.z_max_m)?;
        entry((radial.0.max(axial.0), radial.1.min(axial.1)), t_max)
    }
}

impl Ellipsoid {
    fn intersect(&self, o: &Point3<f64>, d: &Vector3<f64>, t_max: f64) -> Option<f64> {
        // Scale to the unit sphere; t is unchanged by the scaling.
        let p = (o - self.center_m).component_div(&self.radii_m);
        let q = d.component_div(&self.radii_m);
        entry(
            inside_quadratic(q.norm_squared(), p.dot(&q), p.norm_squared() - 1.0)?,
            t_max,
        )
    }
}

impl Cuboid {
    fn intersect(&self, o: &Point3<f64>, d: &Vector3<f64>, t_max: f64) -> Option<f64> {
        let p = self.rotation.inverse_transform_vector(&(o - self.center_m));
        let q = self.rotation.inverse_transform_vector(d);
        let h = &self.half_extents_m;
        let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
        for axis in 0..3 {
            let (a, b) = slab(p[axis], q[axis], -h[axis], h[axis])?;
            t0 = t0.max(a);
            t1 = t1.min(b);
        }
        entry((t0, t1), t_max)
    }

    /// The eight corners (m, world).
    pub fn corners(&self) -> [Point3<f64>; 8] {
        let h = self.half_extents_m;
        std::array::from_fn(|i| {
            let sign = |bit: usize| if i & bit == 0 { -1.0 } else { 1.0 };
            self.center_m
                + self.rotation * Vector3::new(sign(1) * h.x, sign(2) * h.y, sign(4) * h.z)
        })
    }
}

impl Shape {
    /// Distance (m) along the unit direction `dir` from `origin` to where the ray enters the
    /// solid, if that happens within `t_max`.
    pub fn intersect(&self, origin: &Point3<f64>, dir: &Vector3<f64>, t_max: f64) -> Option<f64> {
        match self {
            Shape::Cylinder(c) => c.intersect(origin, dir, t_max),
            Shape::Ellipsoid(e) => e.intersect(origin, dir, t_max),
            Shape::Cuboid(b) => b.intersect(origin, dir, t_max),
        }
    }

    /// A horizontal circle (centre, radius; m) containing the solid's footprint.
    pub fn bounding_circle(&self) -> ([f64; 2], f64) {
        match self {
            Shape::Cylinder(c) => (c.center_xy_m, c.radius_m),
            Shape::Ellipsoid(e) => ([e.center_m.x, e.center_m.y], e.radii_m.x.max(e.radii_m.y)),
            Shape::Cuboid(b) => {
                let c = [b.center_m.x, b.center_m.y];
                let r = b
                    .corners()
                    .iter()
                    .map(|p| (p.x - c[0]).hypot(p.y - c[1]))
                    .fold(0.0, f64::max);
                (c, r)
            }
        }
    }

    /// Horizontal distance (m) from `p` to the solid's footprint (0 inside it). Exact for
    /// cylinders and for boxes turned about z and tilted about their own y axis; ellipsoids
    /// count as their widest circle.
    pub fn footprint_distance_m(&self, p: &Point2<f64>) -> f64 {
        match self {
            Shape::Cylinder(_) | Shape::Ellipsoid(_) => {
                let (c, r) = self.bounding_circle();
                ((p.x - c[0]).hypot(p.y - c[1]) - r).max(0.0)
            }
            Shape::Cuboid(b) => {
                let x_axis = b.rotation * Vector3::x();
                let yaw = x_axis.y.atan2(x_axis.x);
                let (s, c) = yaw.sin_cos();
                let local = |q: &Point3<f64>| {
                    let (dx, dy) = (q.x - b.center_m.x, q.y - b.center_m.y);
                    (c * dx + s * dy, -s * dx + c * dy)
                };
                let (hx, hy) = b
                    .corners()
                    .iter()
                    .map(&local)
                    .fold((0.0f64, 0.0f64), |(hx, hy), (x, y)| {
                        (hx.max(x.abs()), hy.max(y.abs()))
                    });
                let (x, y) = local(&Point3::new(p.x, p.y, 0.0));
                (x.abs() - hx).max(0.0).hypot((y.abs() - hy).max(0.0))
            }
        }
    }

    /// Lowest and highest z (m) of the solid.
    pub fn z_range_m(&self) -> (f64, f64) {
        match self {
            Shape::Cylinder(c) => (c.z_min_m, c.z_max_m),
            Shape::Ellipsoid(e) => (e.center_m.z - e.radii_m.z, e.center_m.z + e.radii_m.z),
            Shape::Cuboid(b) => b
                .corners()
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                    (lo.min(p.z), hi.max(p.z))
                }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray(o: [f64; 3], d: [f64; 3]) -> (Point3<f64>, Vector3<f64>) {
        (Point3::from(o), Vector3::from(d).normalize())
    }

    #[test]
    fn cylinder_side_cap_and_miss() {
        let c = Shape::Cylinder(VerticalCylinder {
            center_xy_m: [10.0, 0.0],
            radius_m: 0.5,
            z_min_m: 0.0,
            z_max_m: 3.0,
        });
        let (o, d) = ray([0.0, 0.0, 1.0], [1.0, 0.0, 0.0]);
        assert!((c.intersect(&o, &d, 40.0).unwrap() - 9.5).abs() < 1e-12);
        // Over the top: misses.
        let (o, d) = ray([0.0, 0.0, 4.0], [1.0, 0.0, 0.0]);
        assert!(c.intersect(&o, &d, 40.0).is_none());
        // Straight down onto the top cap.
        let (o, d) = ray([10.2, 0.0, 5.0], [0.0, 0.0, -1.0]);
        assert!((c.intersect(&o, &d, 40.0).unwrap() - 2.0).abs() < 1e-12);
        // Beyond t_max.
        let (o, d) = ray([0.0, 0.0, 1.0], [1.0, 0.0, 0.0]);
        assert!(c.intersect(&o, &d, 9.0).is_none());
        // From inside: not seen.
        let (o, d) = ray([10.0, 0.0, 1.0], [1.0, 0.0, 0.0]);
        assert!(c.intersect(&o, &d, 40.0).is_none());
    }

    #[test]
    fn ellipsoid_and_rotated_box() {
        let e = Shape::Ellipsoid(Ellipsoid {
            center_m: Point3::new(0.0, 5.0, 2.0),
            radii_m: Vector3::new(2.0, 1.0, 0.5),
        });
        let (o, d) = ray([0.0, 0.0, 2.0], [0.0, 1.0, 0.0]);
        assert!((e.intersect(&o, &d, 40.0).unwrap() - 4.0).abs() < 1e-12);
        let (o, d) = ray([-10.0, 5.0, 2.0], [1.0, 0.0, 0.0]);
        assert!((e.intersect(&o, &d, 40.0).unwrap() - 8.0).abs() < 1e-12);

        // A 4 m × 2 m × 2 m box turned 90° about z: its long side now runs along y.
        let b = Shape::Cuboid(Cuboid {
            center_m: Point3::new(5.0, 0.0, 1.0),
            rotation: UnitQuaternion::from_axis_angle(
                &Vector3::z_axis(),
                std::f64::consts::FRAC_PI_2,
            ),
            half_extents_m: Vector3::new(2.0, 1.0, 1.0),
        });
        let (o, d) = ray([0.0, 0.0, 1.0], [1.0, 0.0, 0.0]);
        assert!((b.intersect(&o, &d, 40.0).unwrap() - 4.0).abs() < 1e-9);
        let (o, d) = ray([5.0, -10.0, 1.0], [0.0, 1.0, 0.0]);
        assert!((b.intersect(&o, &d, 40.0).unwrap() - 8.0).abs() < 1e-9);
        let (c, r) = b.bounding_circle();
        assert!((c[0] - 5.0).abs() < 1e-12 && (r - 5f64.sqrt()).abs() < 1e-9);
        assert!((b.footprint_distance_m(&Point2::new(5.0, 4.0)) - 2.0).abs() < 1e-9);
        assert!((b.footprint_distance_m(&Point2::new(8.0, 0.0)) - 2.0).abs() < 1e-9);
        assert_eq!(b.footprint_distance_m(&Point2::new(5.5, 1.0)), 0.0);
        let (lo, hi) = b.z_range_m();
        assert!((lo - 0.0).abs() < 1e-12 && (hi - 2.0).abs() < 1e-12);
    }
}
