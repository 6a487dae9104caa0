//! The probability grid a scan is scored against, and its max-pooled stack (Hess et al. 2016,
//! section V.C): level h holds, at each cell, the largest value of the 2ʰ × 2ʰ cells from it
//! towards +x and +y, so one lookup bounds every translation a branch of the search covers.

use super::CorrelativeParams;
use crate::Pose2;

/// Cell values: a probability in [0, 1] scaled to 0–255 (a byte keeps a submap's stack small).
pub(super) const FULL: u32 = 255;

/// An exponent past which a return's Gaussian rounds to 0 (e^−6.3 · 255 = 0.47): such cells
/// are left as they are without calling `exp`, the rasterizer's cost.
const NEGLIGIBLE: f64 = 6.3;

/// A probability grid in some frame (a submap's): cell (i, j) covers
/// `[x0 + i·r, x0 + (i+1)·r) × [y0 + j·r, y0 + (j+1)·r)`.
#[derive(Clone, PartialEq)]
pub struct ProbabilityGrid {
    origin: [f64; 2],
    resolution_m: f64,
    width: usize,
    height: usize,
    cells: Vec<u8>,
}

impl ProbabilityGrid {
    /// Rasterizes scans given with their poses in the grid's frame: each return marks the
    /// cells around it with a Gaussian of σ = `params.hit_sigma_m` (the largest value wins);
    /// returns beyond `params.max_range_m` are left out. `None` when there is no return, or
    /// when the grid would exceed `params.max_cells`.
    pub fn from_scans<'a>(
        scans: impl IntoIterator<Item = (Pose2, &'a [[f64; 2]])>,
        params: &CorrelativeParams,
    ) -> Option<ProbabilityGrid> {
        let points = returns_in_range(scans, params);
        let (origin, width, height) = layout(&points, params)?;
        let mut grid = ProbabilityGrid {
            origin,
            resolution_m: params.resolution_m,
            width,
            height,
            cells: vec![0; width * height],
        };
        grid.mark(&points, params);
        Some(grid)
    }

    /// The extent [`Self::from_scans`] would give the same scans (see [`Self::bounds`]),
    /// without rasterizing them.
    pub fn bounds_of<'a>(
        scans: impl IntoIterator<Item = (Pose2, &'a [[f64; 2]])>,
        params: &CorrelativeParams,
    ) -> Option<([f64; 2], [f64; 2])> {
        let (origin, width, height) = layout(&returns_in_range(scans, params), params)?;
        Some(extent(origin, params.resolution_m, width, height))
    }

    /// Marks each point's Gaussian into the cells.
    fn mark(&mut self, points: &[[f64; 2]], params: &CorrelativeParams) {
        let (width, height) = (self.width, self.height);
        let reach = kernel_reach(params);
        // The kernel by cell offset, from the hit's cell centre.
        let inv2s2 = 1.0 / (2.0 * params.hit_sigma_m * params.hit_sigma_m);
        for p in points {
            let (ci, cj) = self.cell_of(*p);
            for dj in -reach..=reach {
                for di in -reach..=reach {
                    let (i, j) = (ci + di, cj + dj);
                    if i < 0 || j < 0 || i >= width as i64 || j >= height as i64 {
                        continue;
                    }
                    let centre = self.centre(i, j);
                    let d2 = (centre[0] - p[0]).powi(2) + (centre[1] - p[1]).powi(2);
                    let x = d2 * inv2s2;
                    let cell = &mut self.cells[j as usize * width + i as usize];
                    // e^x ≥ 1 + x + x²/2 + x³/6 bounds the value from above; where the
                    // cell holds at least that bound less ½, the rounded value cannot
                    // exceed it and `exp` is not called. (One test for both skips: as two
                    // branches the rasterizer measured 40 % slower.)
                    let bound = FULL as f64 / (1.0 + x * (1.0 + x * (0.5 + x / 6.0)));
                    if x > NEGLIGIBLE || f64::from(*cell) >= bound - 0.499 {
                        continue;
                    }
                    let v = ((-x).exp() * FULL as f64).round() as u8;
                    *cell = (*cell).max(v);
                }
            }
        }
    }

    /// The cell holding point `p` (may lie outside the grid).
    pub(super) fn cell_of(&self, p: [f64; 2]) -> (i64, i64) {
        (
            floor_to_i64((p[0] - self.origin[0]) / self.resolution_m),
            floor_to_i64((p[1] - self.origin[1]) / self.resolution_m),
        )
    }

    fn centre(&self, i: i64, j: i64) -> [f64; 2] {
        [
            self.origin[0] + (i as f64 + 0.5) * self.resolution_m,
            self.origin[1] + (j as f64 + 0.5) * self.resolution_m,
        ]
    }

    /// Its size in cells: width (along x) and height.
    pub(super) fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Cell size (m).
    pub fn resolution_m(&self) -> f64 {
        self.resolution_m
    }

    /// The grid's extent in its frame: lower-left and upper-right corners (m).
    pub fn bounds(&self) -> ([f64; 2], [f64; 2]) {
        extent(self.origin, self.resolution_m, self.width, self.height)
    }

    /// The value of cell (i, j), 0 outside the grid.
    #[cfg(test)]
    pub(super) fn get(&self, i: i64, j: i64) -> u8 {
        if i < 0 || j < 0 || i >= self.width as i64 || j >= self.height as i64 {
            return 0;
        }
        self.cells[j as usize * self.width + i as usize]
    }
}

/// The returns of `scans` within `params.max_range_m` of their scan, in the grid's frame.
fn returns_in_range<'a>(
    scans: impl IntoIterator<Item = (Pose2, &'a [[f64; 2]])>,
    params: &CorrelativeParams,
) -> Vec<[f64; 2]> {
    let max_range2 = params.max_range_m * params.max_range_m;
    scans
        .into_iter()
        .flat_map(|(pose, points)| {
            points
                .iter()
                .filter(move |p| p[0] * p[0] + p[1] * p[1] <= max_range2)
                .map(move |&p| pose.transform_point(p))
        })
        .collect()
}

/// Cells a return's Gaussian marks on each side of its own.
fn kernel_reach(params: &CorrelativeParams) -> i64 {
    (3.0 * params.hit_sigma_m / params.resolution_m).ceil() as i64
}

/// The grid that holds `points` with their kernels: origin, width and height; `None` when
/// there is no point or the grid would exceed `params.max_cells`.
fn layout(points: &[[f64; 2]], params: &CorrelativeParams) -> Option<([f64; 2], usize, usize)> {
    let r = params.resolution_m;
    let margin = (kernel_reach(params) + 1) as f64 * r;
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in points {
        for d in 0..2 {
            lo[d] = lo[d].min(p[d]);
            hi[d] = hi[d].max(p[d]);
        }
    }
    if points.is_empty() {
        return None;
    }
    let origin = [lo[0] - margin, lo[1] - margin];
    let width = ((hi[0] + margin - origin[0]) / r).ceil() as usize + 1;
    let height = ((hi[1] + margin - origin[1]) / r).ceil() as usize + 1;
    (width.saturating_mul(height) <= params.max_cells).then_some((origin, width, height))
}

/// A grid's lower-left and upper-right corners (m).
fn extent(
    origin: [f64; 2],
    resolution_m: f64,
    width: usize,
    height: usize,
) -> ([f64; 2], [f64; 2]) {
    let hi = [
        origin[0] + width as f64 * resolution_m,
        origin[1] + height as f64 * resolution_m,
    ];
    (origin, hi)
}

// Its size, not its cells (a submap's are megabytes).
impl std::fmt::Debug for ProbabilityGrid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ProbabilityGrid")
            .field("origin", &self.origin)
            .field("resolution_m", &self.resolution_m)
            .field("width", &self.width)
            .field("height", &self.height)
            .finish_non_exhaustive()
    }
}

/// One max-pooled level: the max over 2ʰ × 2ʰ cells, for cells from −(2ʰ − 1) on (padded so
/// that a window reaching into the grid from below still sees it).
#[derive(Clone, PartialEq)]
struct Level {
    pad: i64,
    width: usize,
    height: usize,
    cells: Vec<u8>,
}

impl Level {
    /// The next level: cell `n` (along each axis, in this level's padded indices) is the max
    /// of this level's cells `n − half` and `n`, where they exist; `half` more cells of
    /// padding below.
    fn pooled(&self, half: usize) -> Level {
        let (width, height) = (self.width + half, self.height + half);
        let mut rows = vec![0u8; width * self.height];
        for (row, out) in self.cells.chunks(self.width).zip(rows.chunks_mut(width)) {
            max_of_shifted(row, out, half);
        }
        // Along y, whole rows at once: shifting the row-major cells by `half` rows shifts
        // every column by `half` cells.
        let mut cells = vec![0u8; width * height];
        max_of_shifted(&rows, &mut cells, half * width);
        Level {
            pad: self.pad + half as i64,
            width,
            height,
            cells,
        }
    }

    fn get(&self, i: i64, j: i64) -> u8 {
        let (i, j) = (i + self.pad, j + self.pad);
        if i < 0 || j < 0 || i >= self.width as i64 || j >= self.height as i64 {
            return 0;
        }
        self.cells[j as usize * self.width + i as usize]
    }

    /// The sum of `cells.cells` shifted by (dx, dy). A shift that keeps the cells' box
    /// inside this level is summed without a test per cell (the common case, and the
    /// search's innermost loop); one that takes it wholly outside is 0.
    fn sum(&self, cells: &Cells, dx: i64, dy: i64) -> u32 {
        let (ox, oy) = (dx + self.pad, dy + self.pad);
        let (w, h) = (self.width as i64, self.height as i64);
        // Saturating: a localize request's prior may put cells 10¹⁸ away (the fuzz target).
        let shifted = |c: i64, o: i64| c.saturating_add(o);
        let ([i0, j0], [i1, j1]) = (cells.lo, cells.hi);
        if shifted(i1, ox) < 0
            || shifted(j1, oy) < 0
            || shifted(i0, ox) >= w
            || shifted(j0, oy) >= h
        {
            return 0;
        }
        if shifted(i0, ox) < 0
            || shifted(j0, oy) < 0
            || shifted(i1, ox) >= w
            || shifted(j1, oy) >= h
        {
            return cells
                .cells
                .iter()
                .map(|&(i, j)| u32::from(self.get(i + dx, j + dy)))
                .sum();
        }
        // The box is inside: every index lies in 0..w·h.
        let base = oy * w + ox;
        cells
            .cells
            .iter()
            .map(|&(i, j)| u32::from(self.cells[(base + j * w + i) as usize]))
            .sum()
    }
}

/// A scan's returns as cells of the grid (at zero offset), with their bounding box.
#[derive(Clone, Debug)]
pub(super) struct Cells {
    cells: Vec<(i64, i64)>,
    lo: [i64; 2],
    hi: [i64; 2],
}

impl Cells {
    pub(super) fn new(cells: Vec<(i64, i64)>) -> Cells {
        let (mut lo, mut hi) = ([i64::MAX; 2], [i64::MIN; 2]);
        for &(i, j) in &cells {
            lo = [lo[0].min(i), lo[1].min(j)];
            hi = [hi[0].max(i), hi[1].max(j)];
        }
        Cells { cells, lo, hi }
    }

    pub(super) fn len(&self) -> usize {
        self.cells.len()
    }

    pub(super) fn iter(&self) -> impl Iterator<Item = &(i64, i64)> {
        self.cells.iter()
    }
}

/// `x.floor() as i64` without the call to libm's `floor` that x86-64's baseline (no SSE4.1)
/// makes of it: the search discretizes every return at every angle. Saturates as `as` does.
fn floor_to_i64(x: f64) -> i64 {
    let t = x as i64;
    t.saturating_sub(i64::from((t as f64) > x))
}

/// `out[n] = max(line[n − half], line[n])`, a missing cell counting 0; `out` is `half` longer.
fn max_of_shifted(line: &[u8], out: &mut [u8], half: usize) {
    let n = line.len();
    debug_assert_eq!(out.len(), n + half);
    let overlap = n.saturating_sub(half);
    out[..n.min(half)].copy_from_slice(&line[..n.min(half)]);
    // A line shorter than the shift leaves cells that neither copy reaches.
    out[n.min(half)..half].fill(0);
    for ((o, &a), &b) in out[half..half + overlap]
        .iter_mut()
        .zip(&line[..overlap])
        .zip(&line[half..])
    {
        *o = a.max(b);
    }
    // Past the line's end only the shifted copy remains (all of it when the line is short).
    let tail = half.max(n);
    out[tail..].copy_from_slice(&line[tail - half..]);
}

/// A grid with its max-pooled levels 0..=depth (level 0 is the grid itself).
#[derive(Clone, PartialEq)]
pub struct PrecomputedGrids {
    grid: ProbabilityGrid,
    levels: Vec<Level>,
}

impl std::fmt::Debug for PrecomputedGrids {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PrecomputedGrids")
            .field("grid", &self.grid)
            .field("depth", &self.depth())
            .finish_non_exhaustive()
    }
}

impl PrecomputedGrids {
    /// Pools `grid` up to level `depth` (windows of 2^depth cells). Each level comes from the
    /// one below by a max over 2 shifted copies along x, then 2 along y, so the stack costs
    /// O(cells · depth), in slices the compiler vectorizes.
    pub fn new(grid: ProbabilityGrid, depth: u32) -> PrecomputedGrids {
        let base = Level {
            pad: 0,
            width: grid.width,
            height: grid.height,
            cells: grid.cells.clone(),
        };
        let mut levels = vec![base];
        for h in 1..=depth {
            let below = &levels[h as usize - 1];
            levels.push(below.pooled(1 << (h - 1)));
        }
        PrecomputedGrids { grid, levels }
    }

    /// The grid at level 0.
    pub fn grid(&self) -> &ProbabilityGrid {
        &self.grid
    }

    /// Bytes its cells take (the grid and every pooled level).
    pub fn cell_bytes(&self) -> usize {
        self.grid.cells.len() + self.levels.iter().map(|l| l.cells.len()).sum::<usize>()
    }

    /// The deepest level (windows of 2^depth cells).
    pub fn depth(&self) -> u32 {
        self.levels.len() as u32 - 1
    }

    /// The largest value of cells (i..i+2ʰ, j..j+2ʰ); 0 beyond the grid.
    #[cfg(test)]
    pub(super) fn get(&self, level: u32, i: i64, j: i64) -> u8 {
        self.levels[level as usize].get(i, j)
    }

    /// The sum over `cells`, shifted by (dx, dy), of each one's value on `level` (0 beyond
    /// the grid).
    pub(super) fn sum(&self, level: u32, cells: &Cells, dx: i64, dy: i64) -> u32 {
        self.levels[level as usize].sum(cells, dx, dy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_to_i64_is_floor() {
        for x in [
            -2.5, -2.0, -1e-12, -0.0, 0.0, 1e-12, 0.999, 1.0, 3.7, -3.7, 1e300, -1e300,
        ] {
            assert_eq!(floor_to_i64(x), x.floor() as i64, "{x}");
        }
        assert_eq!(floor_to_i64(f64::NAN), 0);
    }

    /// 0.1 m cells, returns blurred by σ = 0.1 m: the submaps' grid.
    fn tenth_metre_cells() -> CorrelativeParams {
        CorrelativeParams {
            resolution_m: 0.1,
            hit_sigma_m: 0.1,
            ..CorrelativeParams::default()
        }
    }

    #[test]
    fn the_extent_alone_is_the_grids() {
        let params = CorrelativeParams {
            max_range_m: 5.0,
            ..tenth_metre_cells()
        };
        let near = [[0.0, 0.0], [0.73, 0.21], [1.4, -0.5]];
        let with_far = [[-2.0, 3.1], [9.0, 9.0]];
        let scans = [
            (Pose2::new(0.3, -0.2, 0.4), &near[..]),
            (Pose2::new(-1.0, 2.0, -2.0), &with_far[..]),
        ];
        let grid = ProbabilityGrid::from_scans(scans, &params).expect("points");
        assert_eq!(
            ProbabilityGrid::bounds_of(scans, &params),
            Some(grid.bounds())
        );
        let out_of_range = [(Pose2::IDENTITY, &[[9.0, 9.0]][..])];
        assert_eq!(ProbabilityGrid::bounds_of(out_of_range, &params), None);
        let small = CorrelativeParams {
            max_cells: 10,
            ..params
        };
        assert_eq!(ProbabilityGrid::from_scans(scans, &small), None);
        assert_eq!(ProbabilityGrid::bounds_of(scans, &small), None);
    }

    #[test]
    fn every_cell_holds_its_largest_rounded_gaussian() {
        let params = tenth_metre_cells();
        // Dense, overlapping returns: most cells are marked by many, where skipping `exp`
        // for a cell already high enough is taken most.
        let mut rng = crate::splitmix::SplitMix::new(7);
        let points: Vec<[f64; 2]> = (0..3000)
            .map(|_| [rng.uniform(0.0, 2.0), rng.uniform(-0.7, 0.8)])
            .collect();
        let grid =
            ProbabilityGrid::from_scans([(Pose2::IDENTITY, &points[..])], &params).expect("points");
        let inv2s2 = 1.0 / (2.0 * params.hit_sigma_m * params.hit_sigma_m);
        let reach = kernel_reach(&params);
        let (width, height) = grid.size();
        for j in 0..height as i64 {
            for i in 0..width as i64 {
                let c = grid.centre(i, j);
                let expected = points
                    .iter()
                    .filter(|&&p| {
                        let (pi, pj) = grid.cell_of(p);
                        (pi - i).abs() <= reach && (pj - j).abs() <= reach
                    })
                    .map(|p| {
                        let d2 = (c[0] - p[0]).powi(2) + (c[1] - p[1]).powi(2);
                        ((-d2 * inv2s2).exp() * FULL as f64).round() as u8
                    })
                    .max()
                    .unwrap_or(0);
                assert_eq!(grid.get(i, j), expected, "cell ({i}, {j})");
            }
        }
    }

    #[test]
    fn each_level_is_the_max_over_its_window() {
        let params = tenth_metre_cells();
        let points = [[0.0, 0.0], [0.73, 0.21], [1.4, -0.5], [0.2, 0.9]];
        let grid =
            ProbabilityGrid::from_scans([(Pose2::IDENTITY, &points[..])], &params).expect("points");
        // Deep enough that the windows outgrow the grid.
        let depth = 6;
        assert!(grid.width < 1 << (depth - 1) && grid.height < 1 << (depth - 1));
        let stack = PrecomputedGrids::new(grid.clone(), depth);
        for h in 0..=depth {
            let w = 1i64 << h;
            for j in -w..grid.height as i64 + 1 {
                for i in -w..grid.width as i64 + 1 {
                    let expected = (0..w)
                        .flat_map(|b| (0..w).map(move |a| (a, b)))
                        .map(|(a, b)| grid.get(i + a, j + b))
                        .max()
                        .unwrap_or(0);
                    assert_eq!(stack.get(h, i, j), expected, "level {h} at ({i}, {j})");
                }
            }
        }
        // A hit's own cell is near full; far cells are empty.
        let (i, j) = grid.cell_of([0.73, 0.21]);
        assert!(grid.get(i, j) > 200);
        assert_eq!(grid.get(i + 8, j), 0);
    }
}
