//! The ground: a smooth height field made of Gaussian bumps, and rays against it.
//!
//! The height field is analytic ([`Terrain::height_m`]). Ray casting marches over a cached
//! grid of it (cheap bilinear look-ups, safe steps from a slope bound) and finishes on the
//! analytic field by bisection, so hits are exact to a fraction of a millimetre.

use nalgebra::{Point3, Vector3};

/// One Gaussian bump (positive: hill, negative: hollow) of the height field.
///
/// h(x, y) = `amplitude_m` · exp(−½ (u²/σᵤ² + v²/σᵥ²)), with (u, v) the offset from
/// `center_m` turned by −`yaw_rad` (so σᵤ runs along the direction `yaw_rad`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bump {
    /// Centre (m, world x/y).
    pub center_m: [f64; 2],
    /// Height at the centre (m; negative for a hollow).
    pub amplitude_m: f64,
    /// Standard deviations along and across `yaw_rad` (m).
    pub sigma_m: [f64; 2],
    /// Direction of the first axis (rad, counter-clockwise from x).
    pub yaw_rad: f64,
}

impl Bump {
    /// A round bump.
    pub fn round(center_m: [f64; 2], amplitude_m: f64, sigma_m: f64) -> Bump {
        Bump {
            center_m,
            amplitude_m,
            sigma_m: [sigma_m, sigma_m],
            yaw_rad: 0.0,
        }
    }

    /// Steepest slope of this bump alone (rise over run): A/σ_min · e^{−½}.
    pub fn max_slope(&self) -> f64 {
        self.amplitude_m.abs() / self.sigma_m[0].min(self.sigma_m[1]) * (-0.5f64).exp()
    }
}

/// Bumps prepared for fast evaluation.
#[derive(Clone, Copy, Debug)]
struct PreparedBump {
    cx: f64,
    cy: f64,
    amplitude: f64,
    cos: f64,
    sin: f64,
    inv_su2: f64,
    inv_sv2: f64,
    /// Radius beyond which the bump is below 1e-9 of its amplitude (m).
    reach: f64,
}

impl PreparedBump {
    #[inline]
    fn at(&self, x: f64, y: f64) -> f64 {
        let (dx, dy) = (x - self.cx, y - self.cy);
        let u = self.cos * dx + self.sin * dy;
        let v = -self.sin * dx + self.cos * dy;
        self.amplitude * (-0.5 * (u * u * self.inv_su2 + v * v * self.inv_sv2)).exp()
    }
}

/// Grid spacing of the cached height field (m).
const GRID_CELL_M: f64 = 0.5;
/// The grid may differ from the analytic field by up to half of this (m); steps keep this
/// much clearance so marching on the grid never skips a true crossing.
const GRID_MARGIN_M: f64 = 0.02;
/// Smallest step of the march (m): below this a step is taken anyway and a sign change is
/// resolved by bisection.
const MIN_STEP_M: f64 = 0.05;
/// Root finding stops when the bracket is shorter than this (m) ...
const BISECT_M: f64 = 1e-4;
/// ... or the ray is this close to the ground, vertically (m).
const GAP_TOLERANCE_M: f64 = 1e-5;

/// A smooth height field over the whole plane, cached on a grid over `bounds`.
#[derive(Clone, Debug)]
pub struct Terrain {
    bumps: Vec<Bump>,
    prepared: Vec<PreparedBump>,
    origin: [f64; 2],
    nx: usize,
    ny: usize,
    grid: Vec<f32>,
    min_height_m: f64,
    max_height_m: f64,
    /// Upper bound of the slope (rise over run) of both the grid and the analytic field.
    slope_bound: f64,
    /// Per block of `BLOCK` × `BLOCK` grid cells: lowest and highest node, and the grid's
    /// slope bound there, so that a ray over flat ground takes long steps.
    blocks: Vec<BlockStats>,
    blocks_x: usize,
    blocks_y: usize,
}

/// Bounds of the cached grid over one block of cells.
#[derive(Clone, Copy, Debug, Default)]
struct BlockStats {
    min_m: f32,
    max_m: f32,
    slope: f32,
}

/// Grid cells per block side.
const BLOCK: usize = 16;

/// Height and slope bounds of the ground under one ray, from [`Terrain::bounds_along`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroundBounds {
    /// Lower bound of the ground height under the ray's horizontal track (m).
    pub min_height_m: f64,
    /// Upper bound of the ground height there (m).
    pub max_height_m: f64,
    /// Slope bound of the cached grid there (rise over run).
    grid_slope: f64,
}

impl Terrain {
    /// The field of `bumps` (zero elsewhere), cached over `[x0, y0, x1, y1]` (m). Outside the
    /// cache, rays still work, on the analytic field only (slower).
    pub fn new(bumps: Vec<Bump>, bounds_m: [f64; 4]) -> Terrain {
        let prepared: Vec<PreparedBump> = bumps
            .iter()
            .map(|b| {
                let (sin, cos) = b.yaw_rad.sin_cos();
                PreparedBump {
                    cx: b.center_m[0],
                    cy: b.center_m[1],
                    amplitude: b.amplitude_m,
                    cos,
                    sin,
                    inv_su2: 1.0 / (b.sigma_m[0] * b.sigma_m[0]),
                    inv_sv2: 1.0 / (b.sigma_m[1] * b.sigma_m[1]),
                    // exp(−½ k²) < 1e-9 for k > 6.5.
                    reach: 6.5 * b.sigma_m[0].max(b.sigma_m[1]),
                }
            })
            .collect();
        let [x0, y0, x1, y1] = bounds_m;
        let nx = ((x1 - x0) / GRID_CELL_M).ceil() as usize + 1;
        let ny = ((y1 - y0) / GRID_CELL_M).ceil() as usize + 1;
        let mut grid = vec![0.0f64; nx * ny];
        for b in &prepared {
            // Only the nodes the bump reaches: keeps construction cheap.
            let cells = |c: f64, o: f64, n: usize| {
                let lo = ((c - b.reach - o) / GRID_CELL_M).floor().max(0.0) as usize;
                let hi = (((c + b.reach - o) / GRID_CELL_M).ceil().max(0.0) as usize).min(n - 1);
                lo..=hi
            };
            for j in cells(b.cy, y0, ny) {
                let y = y0 + j as f64 * GRID_CELL_M;
                for i in cells(b.cx, x0, nx) {
                    grid[j * nx + i] += b.at(x0 + i as f64 * GRID_CELL_M, y);
                }
            }
        }
        let (mut lo, mut hi, mut max_step) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
        for j in 0..ny {
            for i in 0..nx {
                let h = grid[j * nx + i];
                lo = lo.min(h);
                hi = hi.max(h);
                if i + 1 < nx {
                    max_step = max_step.max((grid[j * nx + i + 1] - h).abs());
                }
                if j + 1 < ny {
                    max_step = max_step.max((grid[(j + 1) * nx + i] - h).abs());
                }
            }
        }
        // The bilinear patch's gradient is bounded per axis by the largest node difference;
        // the analytic field by the sum of the bumps' slopes. Take the smaller, with slack.
        let grid_slope = std::f64::consts::SQRT_2 * max_step / GRID_CELL_M;
        let sum_slope: f64 = bumps.iter().map(Bump::max_slope).sum();
        let slope_bound = grid_slope.min(sum_slope) * 1.1 + 0.02;
        // Outside the grid the field is ~0 if every bump fits inside it; otherwise only the
        // sums of the amplitudes bound it.
        let contained = prepared.iter().all(|b| {
            b.cx - b.reach >= x0
                && b.cx + b.reach <= x1
                && b.cy - b.reach >= y0
                && b.cy + b.reach <= y1
        });
        let (outside_lo, outside_hi) = if contained {
            (0.0, 0.0)
        } else {
            (
                bumps.iter().map(|b| b.amplitude_m.min(0.0)).sum(),
                bumps.iter().map(|b| b.amplitude_m.max(0.0)).sum(),
            )
        };
        let (blocks_x, blocks_y) = ((nx - 1).div_ceil(BLOCK), (ny - 1).div_ceil(BLOCK));
        let mut blocks = Vec::with_capacity(blocks_x * blocks_y);
        for by in 0..blocks_y {
            for bx in 0..blocks_x {
                let (i0, i1) = (bx * BLOCK, ((bx + 1) * BLOCK).min(nx - 1));
                let (j0, j1) = (by * BLOCK, ((by + 1) * BLOCK).min(ny - 1));
                let (mut lo, mut hi, mut step) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
                for j in j0..=j1 {
                    for i in i0..=i1 {
                        let h = grid[j * nx + i];
                        lo = lo.min(h);
                        hi = hi.max(h);
                        if i < i1 {
                            step = step.max((grid[j * nx + i + 1] - h).abs());
                        }
                        if j < j1 {
                            step = step.max((grid[(j + 1) * nx + i] - h).abs());
                        }
                    }
                }
                blocks.push(BlockStats {
                    min_m: lo as f32,
                    max_m: hi as f32,
                    // Rounded up: a bound must not shrink in f32.
                    slope: (std::f64::consts::SQRT_2 * step / GRID_CELL_M * 1.001 + 1e-6) as f32,
                });
            }
        }
        Terrain {
            bumps,
            prepared,
            origin: [x0, y0],
            nx,
            ny,
            grid: grid.into_iter().map(|h| h as f32).collect(),
            min_height_m: lo.min(outside_lo) - GRID_MARGIN_M,
            max_height_m: hi.max(outside_hi) + GRID_MARGIN_M,
            slope_bound,
            blocks,
            blocks_x,
            blocks_y,
        }
    }

    /// Bounds of the ground under the horizontal track of the ray from `origin` along `dir`
    /// up to `t_max` (m): from the blocks its bounding box touches, or the whole field's
    /// bounds if it leaves the cache.
    pub fn bounds_along(
        &self,
        origin: &Point3<f64>,
        dir: &Vector3<f64>,
        t_max: f64,
    ) -> GroundBounds {
        let everywhere = GroundBounds {
            min_height_m: self.min_height_m,
            max_height_m: self.max_height_m,
            grid_slope: self.slope_bound,
        };
        let block_m = BLOCK as f64 * GRID_CELL_M;
        let end = origin + dir * t_max;
        let to_block = |v: f64, o: f64| ((v - o) / block_m).floor();
        let (bx0, bx1) = (
            to_block(origin.x.min(end.x), self.origin[0]),
            to_block(origin.x.max(end.x), self.origin[0]),
        );
        let (by0, by1) = (
            to_block(origin.y.min(end.y), self.origin[1]),
            to_block(origin.y.max(end.y), self.origin[1]),
        );
        if !(bx0 >= 0.0 && by0 >= 0.0 && bx1 < self.blocks_x as f64 && by1 < self.blocks_y as f64) {
            return everywhere;
        }
        let (mut lo, mut hi, mut slope) = (f32::INFINITY, f32::NEG_INFINITY, 0.0f32);
        for by in by0 as usize..=by1 as usize {
            for b in
                &self.blocks[by * self.blocks_x + bx0 as usize..=by * self.blocks_x + bx1 as usize]
            {
                lo = lo.min(b.min_m);
                hi = hi.max(b.max_m);
                slope = slope.max(b.slope);
            }
        }
        GroundBounds {
            min_height_m: lo as f64 - GRID_MARGIN_M,
            max_height_m: hi as f64 + GRID_MARGIN_M,
            grid_slope: slope as f64,
        }
    }

    /// The bumps the field is made of.
    pub fn bumps(&self) -> &[Bump] {
        &self.bumps
    }

    /// Ground height (m, world z) at (x, y), from the analytic field.
    pub fn height_m(&self, x: f64, y: f64) -> f64 {
        self.prepared.iter().map(|b| b.at(x, y)).sum()
    }

    /// Gradient (∂h/∂x, ∂h/∂y) of the analytic field by central differences.
    pub fn gradient(&self, x: f64, y: f64) -> [f64; 2] {
        let e = 0.01;
        [
            (self.height_m(x + e, y) - self.height_m(x - e, y)) / (2.0 * e),
            (self.height_m(x, y + e) - self.height_m(x, y - e)) / (2.0 * e),
        ]
    }

    /// Upper bound of the terrain slope (rise over run) everywhere.
    pub fn slope_bound(&self) -> f64 {
        self.slope_bound
    }

    /// Highest ground anywhere (m, world z), with a small margin.
    pub fn max_height_m(&self) -> f64 {
        self.max_height_m
    }

    /// Lowest ground anywhere (m, world z).
    pub fn min_height_m(&self) -> f64 {
        self.min_height_m
    }

    /// Height from the cached grid (bilinear), or the analytic field outside it.
    #[inline]
    fn cached_height_m(&self, x: f64, y: f64) -> f64 {
        let fx = (x - self.origin[0]) / GRID_CELL_M;
        let fy = (y - self.origin[1]) / GRID_CELL_M;
        if !(fx >= 0.0 && fy >= 0.0 && fx < (self.nx - 1) as f64 && fy < (self.ny - 1) as f64) {
            return self.height_m(x, y);
        }
        let (i, j) = (fx as usize, fy as usize);
        let (tx, ty) = (fx - i as f64, fy - j as f64);
        let k = j * self.nx + i;
        let (h00, h10) = (self.grid[k] as f64, self.grid[k + 1] as f64);
        let (h01, h11) = (
            self.grid[k + self.nx] as f64,
            self.grid[k + self.nx + 1] as f64,
        );
        let bottom = h00 + (h10 - h00) * tx;
        let top = h01 + (h11 - h01) * tx;
        bottom + (top - bottom) * ty
    }

    /// Distance (m) along the unit direction `dir` at which the ray from `origin` meets the
    /// ground, if within `t_max`. A ray starting below the ground hits at 0.
    pub fn raycast(&self, origin: &Point3<f64>, dir: &Vector3<f64>, t_max: f64) -> Option<f64> {
        let bounds = self.bounds_along(origin, dir, t_max);
        self.raycast_within(origin, dir, t_max, &bounds)
    }

    /// [`Terrain::raycast`] with the ray's ground bounds already known (for a `t_max` no
    /// longer than the one they were taken for).
    pub fn raycast_within(
        &self,
        origin: &Point3<f64>,
        dir: &Vector3<f64>,
        t_max: f64,
        bounds: &GroundBounds,
    ) -> Option<f64> {
        if dir.z >= 0.0 && origin.z > bounds.max_height_m {
            return None;
        }
        let true_gap = |t: f64| {
            let p = origin + dir * t;
            p.z - self.height_m(p.x, p.y)
        };
        let grid_gap = |t: f64| {
            let p = origin + dir * t;
            p.z - self.cached_height_m(p.x, p.y)
        };
        // Clearly above the ground by the grid, or else by the field: the ray starts above.
        if grid_gap(0.0) <= 2.0 * GRID_MARGIN_M && true_gap(0.0) <= 0.0 {
            return Some(0.0);
        }
        // The fastest the gap between ray and ground can shrink per metre of ray.
        let closing = self.slope_bound * dir.x.hypot(dir.y) - dir.z;
        if closing <= 0.0 {
            return None;
        }
        // Fast path: march on the grid with its local slope bound, then settle the crossing
        // on the analytic field.
        let grid_closing = bounds.grid_slope * dir.x.hypot(dir.y) - dir.z;
        let mut t = 0.0;
        let mut gap = grid_gap(0.0);
        if gap > 0.0 {
            loop {
                if dir.z >= 0.0 && origin.z + dir.z * t > bounds.max_height_m {
                    return None;
                }
                let step = if grid_closing > 0.0 {
                    gap / grid_closing
                } else {
                    t_max
                };
                let next = (t + step.max(MIN_STEP_M)).min(t_max);
                let next_gap = grid_gap(next);
                if next_gap <= 0.0 {
                    let (lo, hi) = (true_gap(t), true_gap(next));
                    if lo > 0.0 && hi <= 0.0 {
                        return Some(regula_falsi(t, next, lo, hi, &true_gap));
                    }
                    // Grid and field disagree here (a ray grazing the ground): take the
                    // careful way.
                    break;
                }
                if next >= t_max {
                    return None;
                }
                (t, gap) = (next, next_gap);
            }
        }
        self.march_analytic(&true_gap, &grid_gap, closing, dir.z, origin.z, t_max)
    }

    /// The careful march: safe steps on the grid while far from the ground, on the analytic
    /// field near it, so that no crossing is missed.
    fn march_analytic(
        &self,
        true_gap: &impl Fn(f64) -> f64,
        grid_gap: &impl Fn(f64) -> f64,
        closing: f64,
        dir_z: f64,
        origin_z: f64,
        t_max: f64,
    ) -> Option<f64> {
        let mut t = 0.0;
        loop {
            if dir_z >= 0.0 && origin_z + dir_z * t > self.max_height_m {
                return None;
            }
            // A lower bound of the true clearance at t: far from the ground the grid is good
            // enough; near it only the analytic field is.
            let g = grid_gap(t);
            let clearance = if g > 2.0 * GRID_MARGIN_M {
                g - GRID_MARGIN_M
            } else {
                true_gap(t)
            };
            // Within clearance / closing the ray cannot reach the ground (slope bound).
            let safe = clearance / closing;
            let next = t + safe.max(MIN_STEP_M);
            if safe < MIN_STEP_M {
                // A forced step may cross the ground: look, and bracket the crossing.
                let end = next.min(t_max);
                let g_end = true_gap(end);
                if g_end <= 0.0 {
                    return Some(regula_falsi(t, end, true_gap(t), g_end, true_gap));
                }
            }
            if next >= t_max {
                return None;
            }
            t = next;
        }
    }
}

/// The crossing of `gap` in `[lo, hi]` (positive `g_lo` at `lo`, `g_hi` ≤ 0 at `hi`) by the
/// Illinois variant of regula falsi: a few evaluations on a smooth field.
fn regula_falsi(
    mut lo: f64,
    mut hi: f64,
    mut g_lo: f64,
    mut g_hi: f64,
    gap: &impl Fn(f64) -> f64,
) -> f64 {
    let mut last_side = 0;
    for _ in 0..60 {
        let t = if g_lo > g_hi {
            (lo * g_hi - hi * g_lo) / (g_hi - g_lo)
        } else {
            0.5 * (lo + hi)
        };
        let g = gap(t);
        if g.abs() < GAP_TOLERANCE_M || hi - lo < BISECT_M {
            return t;
        }
        if g > 0.0 {
            (lo, g_lo) = (t, g);
            if last_side == 1 {
                g_hi *= 0.5;
            }
            last_side = 1;
        } else {
            (hi, g_hi) = (t, g);
            if last_side == -1 {
                g_lo *= 0.5;
            }
            last_side = -1;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn hills() -> Terrain {
        Terrain::new(
            vec![
                Bump::round([0.0, 0.0], 4.5, 8.0),
                Bump {
                    center_m: [20.0, -5.0],
                    amplitude_m: -2.5,
                    sigma_m: [5.0, 12.0],
                    yaw_rad: 0.4,
                },
            ],
            [-60.0, -60.0, 60.0, 60.0],
        )
    }

    #[test]
    fn grid_matches_the_analytic_field() {
        let t = hills();
        let mut rng = Rng::new(1);
        for _ in 0..10_000 {
            let (x, y) = (rng.range(-59.0, 59.0), rng.range(-59.0, 59.0));
            let err = (t.cached_height_m(x, y) - t.height_m(x, y)).abs();
            assert!(err < GRID_MARGIN_M / 2.0, "grid error {err} at {x}, {y}");
        }
        let [gx, gy] = t.gradient(5.0, 3.0);
        assert!(gx.hypot(gy) <= t.slope_bound());
    }

    #[test]
    fn rays_land_on_the_field() {
        let t = hills();
        let mut rng = Rng::new(2);
        let mut hits = 0;
        for _ in 0..2_000 {
            let (x, y) = (rng.range(-40.0, 40.0), rng.range(-40.0, 40.0));
            let origin = Point3::new(x, y, t.height_m(x, y) + 1.2);
            let (az, el) = (rng.range(-3.2, 3.2), rng.range(-1.0, 0.5));
            let dir = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            if let Some(range) = t.raycast(&origin, &dir, 40.0) {
                hits += 1;
                let p = origin + dir * range;
                assert!((p.z - t.height_m(p.x, p.y)).abs() < 0.005, "off the ground");
                // No earlier crossing: sample the ray before the hit.
                for k in 1..200 {
                    let q = origin + dir * (range * k as f64 / 200.0);
                    assert!(
                        q.z - t.height_m(q.x, q.y) > -0.005,
                        "went through the ground"
                    );
                }
            }
        }
        assert!(hits > 800, "only {hits} hits");
        let down = t.raycast(&Point3::new(3.0, 4.0, 10.0), &-Vector3::z(), 40.0);
        assert!((down.unwrap() - (10.0 - t.height_m(3.0, 4.0))).abs() < 1e-3);
        assert!(
            t.raycast(&Point3::new(3.0, 4.0, 10.0), &Vector3::z(), 40.0)
                .is_none()
        );
    }
}
