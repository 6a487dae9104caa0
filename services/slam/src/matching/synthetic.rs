//! Synthetic 2D scenes — straight walls and round trunks — ray cast into range scans with
//! known poses, for tests and benchmarks of scan matching. Deterministic: the range noise
//! comes from a seeded generator.

use crate::Pose2;
use crate::splitmix::SplitMix;

/// A plane scene in map coordinates (m).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scene {
    /// Wall segments, end to end.
    pub walls: Vec<[[f64; 2]; 2]>,
    /// Trunks (poles, trees): centre and radius.
    pub trunks: Vec<([f64; 2], f64)>,
}

impl Scene {
    /// An outdoor-like scene around the origin, about 40 m × 30 m: an L-shaped building,
    /// a fence, a parked car (box) and twenty trees of 0.15–0.4 m radius.
    pub fn park() -> Scene {
        let mut rng = SplitMix::new(7);
        let mut walls = vec![
            [[-12.0, 8.0], [10.0, 8.0]],
            [[10.0, 8.0], [10.0, 15.0]],
            [[-12.0, 8.0], [-12.0, -6.0]],
            [[14.0, -12.0], [20.0, 6.0]],
        ];
        // A car: a 4.2 m × 1.8 m box.
        let car = [[4.0, -7.0], [8.2, -7.0], [8.2, -5.2], [4.0, -5.2]];
        for i in 0..4 {
            walls.push([car[i], car[(i + 1) % 4]]);
        }
        let mut trunks = Vec::new();
        while trunks.len() < 20 {
            let c = [rng.uniform(-18.0, 18.0), rng.uniform(-14.0, 6.0)];
            // Keep the robot's area (radius 3 m) and the car free.
            let clear_of_car = !(3.0..9.5).contains(&c[0]) || !(-8.0..-4.0).contains(&c[1]);
            if c[0].hypot(c[1]) > 3.0 && clear_of_car {
                trunks.push((c, rng.uniform(0.15, 0.4)));
            }
        }
        Scene { walls, trunks }
    }

    /// A straight corridor along x, `width_m` wide and `length_m` long, centred on the
    /// origin, with no end walls.
    pub fn corridor(width_m: f64, length_m: f64) -> Scene {
        let (h, l) = (width_m / 2.0, length_m / 2.0);
        Scene {
            walls: vec![[[-l, -h], [l, -h]], [[-l, h], [l, h]]],
            trunks: Vec::new(),
        }
    }

    /// Distance along the unit ray `origin + s·dir` to the first surface, if any (m).
    pub fn range(&self, origin: [f64; 2], dir: [f64; 2]) -> Option<f64> {
        let walls = self.walls.iter().filter_map(|&[a, b]| {
            // Solve origin + s·dir = a + u·(b − a) for s ≥ 0, u ∈ [0, 1].
            let e = [b[0] - a[0], b[1] - a[1]];
            let den = dir[0] * e[1] - dir[1] * e[0];
            if den.abs() < 1e-12 {
                return None;
            }
            let w = [a[0] - origin[0], a[1] - origin[1]];
            let s = (w[0] * e[1] - w[1] * e[0]) / den;
            let u = (w[0] * dir[1] - w[1] * dir[0]) / den;
            (s > 0.0 && (0.0..=1.0).contains(&u)).then_some(s)
        });
        let trunks = self.trunks.iter().filter_map(|&(c, radius)| {
            let w = [c[0] - origin[0], c[1] - origin[1]];
            let along = w[0] * dir[0] + w[1] * dir[1];
            let off2 = w[0] * w[0] + w[1] * w[1] - along * along;
            let half2 = radius * radius - off2;
            let s = along - half2.max(0.0).sqrt();
            (half2 >= 0.0 && s > 0.0).then_some(s)
        });
        walls.chain(trunks).min_by(f64::total_cmp)
    }

    /// The ranges a scanner at `pose` measures at `bearings_rad` (scanner frame), with
    /// Gaussian noise of `noise_std_m`; `max_range_m` where nothing is hit within it.
    pub fn scan(
        &self,
        pose: &Pose2,
        bearings_rad: &[f32],
        max_range_m: f32,
        noise_std_m: f64,
        seed: u64,
    ) -> Vec<f32> {
        let mut rng = SplitMix::new(seed);
        bearings_rad
            .iter()
            .map(|&b| {
                let angle = pose.theta + f64::from(b);
                let noise = noise_std_m * rng.gaussian();
                match self.range([pose.x, pose.y], [angle.cos(), angle.sin()]) {
                    Some(r) if r + noise < f64::from(max_range_m) => (r + noise) as f32,
                    _ => max_range_m,
                }
            })
            .collect()
    }
}

/// `count` bearings from `first_rad` in steps of `step_rad`.
pub fn uniform_bearings(count: usize, first_rad: f64, step_rad: f64) -> Vec<f32> {
    (0..count)
        .map(|i| (first_rad + step_rad * i as f64) as f32)
        .collect()
}

/// Uniform bearings over `fov_rad` centred ahead, each moved by up to ±`jitter` of a step
/// and one in `drop_every` removed: the uneven bearings of a leveled scan.
pub fn uneven_bearings(
    count: usize,
    fov_rad: f64,
    jitter: f64,
    drop_every: usize,
    seed: u64,
) -> Vec<f32> {
    let mut rng = SplitMix::new(seed);
    let step = fov_rad / count as f64;
    (0..count)
        .filter(|i| drop_every == 0 || i % drop_every != drop_every / 2)
        .map(|i| (-fov_rad / 2.0 + step * (i as f64 + 0.5 + rng.uniform(-jitter, jitter))) as f32)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rays_hit_walls_and_trunks_first() {
        let scene = Scene {
            walls: vec![[[5.0, -1.0], [5.0, 1.0]]],
            trunks: vec![([3.0, 0.0], 0.5)],
        };
        assert_eq!(scene.range([0.0, 0.0], [1.0, 0.0]), Some(2.5));
        let up = scene.range([0.0, 0.0], [0.0, 1.0]);
        assert_eq!(up, None);
        let r = scene.range([0.0, 0.9], [1.0, 0.0]).expect("wall");
        assert!((r - 5.0).abs() < 1e-12);
    }
}
