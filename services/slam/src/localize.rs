//! Localization on a frozen map (a map version): where a leveled scan was taken, with no
//! network to grow. The map's scans are rasterized once into square tiles of probability
//! grids (`tiles`); a scan is found in them by the correlative branch and bound of loop
//! closure (`matching::correlative`), in a window around a prior or, with none, over every
//! tile and heading (a global search, with the same ambiguity test as loop closure), then
//! refined by IDC and point-to-line refinement against the map's nearest scans and gated
//! like a closure. [`Tracker`] follows a robot from node to node: its odometry since the
//! last fix is the prior, and a robot lost for too long is searched for globally.
//!
//! This goes beyond the paper, which only maps (docs/slam.md, "Localization on a map
//! version").

#[cfg(test)]
mod tests;
mod tiles;
mod track;

pub use track::{TrackParams, TrackStatus, TrackStep, Tracker};

use crate::matching::correlative::{
    CorrelativeMatch, CorrelativeParams, Exclusion, SearchWindow, runner_up, search,
};
use crate::matching::{IdcParams, QualityGate, Reference, RefineParams, Scan2, accept, idc};
use crate::{Pose2, wrap_angle};
use serde::{Deserialize, Serialize};
use tiles::{NodeIndex, Tile};

/// How a map is rasterized and a scan searched in it. The defaults suit leveled scans of an
/// outdoor site (landmarks within 20 m, nodes about a metre apart).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LocalizeParams {
    /// Rasterization and search: cell size, hit blur, range used.
    pub grid: CorrelativeParams,
    /// Side of a tile (m): the map's grids are cut into squares of this side (each with a
    /// margin of `grid.max_range_m` around it), so memory follows the area mapped.
    pub tile_m: f64,
    /// A windowed search's best pose must score at least this (mean cell value under the
    /// returns, 0–1)…
    pub min_score: f64,
    /// …and a global one this: a search over every place scores more wrong poses.
    pub global_min_score: f64,
    /// A global result is refused when a pose elsewhere (beyond `ambiguity_radius_m`) scores
    /// at least this share of the best: a row of like trees fits several places.
    pub max_runner_up_ratio: f64,
    /// See `max_runner_up_ratio` (m).
    pub ambiguity_radius_m: f64,
    /// A rival is refined like the best pose; it makes the scan ambiguous only when its
    /// refined quality is within this of the best's (free space its returns fall in lowers
    /// it)…
    pub quality_margin: f64,
    /// …checking at most this many rivals (the best scoring); more than this is ambiguous.
    pub max_rivals_refined: usize,
    /// A prior that may be wrong ([`LocalizationMap::relocalize`]): its window's best pose
    /// must refine to at least this quality, or the whole map is searched. A wrong prior
    /// finds poses that fit part of the scan (a wall, a row of trees): in the park they
    /// refined to 0.81–0.86, right ones to 0.93 and more.
    pub prior_min_quality: f64,
    /// The map's scans nearest the found pose that refine it (IDC against the nearest, then
    /// point-to-line against all of them)…
    pub reference_nodes: usize,
    /// …among those within this distance of it (m).
    pub reference_radius_m: f64,
    /// The refinement may move the correlative pose by at most this (m)…
    pub refine_max_shift_m: f64,
    /// …and turn it by at most this (rad); beyond, the two disagree and the scan is not
    /// found.
    pub refine_max_turn_rad: f64,
    /// Scan matching of the refinement.
    pub idc: IdcParams,
    /// Point-to-line refinement after IDC.
    pub refine: RefineParams,
    /// The refined match must pass this gate. Unlike a loop closure's, it does not ask for
    /// convergence: the refinement only polishes a pose the search found to a cell, and must
    /// agree with it (`refine_max_shift_m`, `refine_max_turn_rad`).
    pub gate: QualityGate,
}

impl Default for LocalizeParams {
    fn default() -> Self {
        LocalizeParams {
            grid: CorrelativeParams {
                resolution_m: 0.1,
                hit_sigma_m: 0.1,
                max_range_m: 20.0,
                max_depth: 6,
                ..CorrelativeParams::default()
            },
            tile_m: 64.0,
            min_score: 0.55,
            global_min_score: 0.6,
            max_runner_up_ratio: 0.85,
            ambiguity_radius_m: 1.5,
            quality_margin: 0.1,
            max_rivals_refined: 4,
            prior_min_quality: 0.9,
            reference_nodes: 3,
            reference_radius_m: 8.0,
            refine_max_shift_m: 0.3,
            refine_max_turn_rad: 3f64.to_radians(),
            idc: IdcParams::default(),
            refine: RefineParams::default(),
            gate: QualityGate {
                require_converged: false,
                ..QualityGate::default()
            },
        }
    }
}

/// What the caller knows of the pose: a guess and how far off it may be.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Prior {
    /// The scan frame's guessed pose in the map frame.
    pub pose: Pose2,
    /// The true position is within this of the guess in x and in y (m).
    pub linear_m: f64,
    /// The true heading is within this of the guess (rad).
    pub angular_rad: f64,
}

/// Which search found a pose.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum SearchKind {
    /// In the prior's window.
    Window,
    /// Over the whole map, every heading.
    Global,
}

/// A scan found in the map.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Localization {
    /// The scan frame's pose in the map frame.
    pub pose: Pose2,
    /// Covariance of (x, y, θ) in the map frame (m², m·rad, rad²), from the refining match.
    pub covariance: [[f64; 3]; 3],
    /// The correlative score of the pose (mean cell value under the returns, 0–1).
    pub score: f64,
    /// The refining match's quality (0–1, see `matching::Match::quality`).
    pub quality: f64,
    /// The search that found it.
    pub search: SearchKind,
    /// The map's scan it was refined against (its index in the map).
    pub reference: usize,
    /// Candidates the branch and bound scored: the search's cost.
    pub candidates: usize,
}

/// Why a scan was not found.
#[derive(Clone, Debug, PartialEq)]
pub enum LocalizeError {
    /// The map has no scan with a return.
    EmptyMap,
    /// The scan has no return within range.
    NoReturns(f64),
    /// The prior lies outside the mapped area.
    OutsideMap {
        /// The prior's x (m).
        x: f64,
        /// The prior's y (m).
        y: f64,
    },
    /// No pose scored enough, or its refinement failed.
    NotFound {
        /// The score asked for.
        min_score: f64,
        /// The best correlative score, when one passed but its refinement failed.
        best: Option<f64>,
    },
    /// Another place scores nearly as well.
    Ambiguous {
        /// The best score.
        score: f64,
        /// The best score elsewhere.
        rival: f64,
        /// How far apart the two are (m).
        distance_m: f64,
    },
    /// A parameter is out of range.
    InvalidParams(String),
}

impl std::fmt::Display for LocalizeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LocalizeError::EmptyMap => write!(f, "the map has no scan to localize against"),
            LocalizeError::NoReturns(range) => {
                write!(f, "the scan has no return within {range} m")
            }
            LocalizeError::OutsideMap { x, y } => {
                write!(f, "the prior ({x:.1}, {y:.1}) is outside the map")
            }
            LocalizeError::NotFound { min_score, best } => match best {
                Some(best) => write!(
                    f,
                    "not found: the best pose scores {best:.3} but does not refine"
                ),
                None => write!(f, "not found: no pose scores {min_score}"),
            },
            LocalizeError::Ambiguous {
                score,
                rival,
                distance_m,
            } => write!(
                f,
                "ambiguous: {score:.3} here, {rival:.3} {distance_m:.1} m away"
            ),
            LocalizeError::InvalidParams(what) => write!(f, "localize parameters: {what}"),
        }
    }
}

impl std::error::Error for LocalizeError {}

/// A frozen map rasterized for localization: the map's scans at their poses, cut into tiles.
#[derive(Debug)]
pub struct LocalizationMap {
    params: LocalizeParams,
    scans: Vec<(Pose2, Scan2)>,
    nodes: NodeIndex,
    tiles: Vec<Tile>,
}

impl LocalizationMap {
    /// Rasterizes `scans` (each with its pose in the map frame; matching cuts them at the
    /// caller's range). Costs O(returns) time and a byte per cell per pooled level.
    pub fn new(
        scans: Vec<(Pose2, Scan2)>,
        params: LocalizeParams,
    ) -> Result<LocalizationMap, LocalizeError> {
        let p = &params;
        let positive = [
            ("tile_m", p.tile_m),
            ("grid.resolution_m", p.grid.resolution_m),
            ("grid.max_range_m", p.grid.max_range_m),
            ("reference_radius_m", p.reference_radius_m),
            ("ambiguity_radius_m", p.ambiguity_radius_m),
        ];
        if let Some((name, v)) = positive.iter().find(|(_, v)| !(v.is_finite() && *v > 0.0)) {
            return Err(LocalizeError::InvalidParams(format!("{name} = {v}")));
        }
        if p.reference_nodes == 0 {
            return Err(LocalizeError::InvalidParams("reference_nodes = 0".into()));
        }
        let tiles = tiles::build(&scans, &params);
        if tiles.is_empty() {
            return Err(LocalizeError::EmptyMap);
        }
        let nodes = NodeIndex::new(&scans, params.reference_radius_m);
        Ok(LocalizationMap {
            params,
            scans,
            nodes,
            tiles,
        })
    }

    /// The parameters it was built with.
    pub fn params(&self) -> &LocalizeParams {
        &self.params
    }

    /// The map's scans.
    pub fn len(&self) -> usize {
        self.scans.len()
    }

    /// True when the map has no scan (never: [`Self::new`] refuses an empty map).
    pub fn is_empty(&self) -> bool {
        self.scans.is_empty()
    }

    /// Its tiles.
    pub fn tile_count(&self) -> usize {
        self.tiles.len()
    }

    /// Bytes of its grids (every tile, every pooled level).
    pub fn grid_bytes(&self) -> usize {
        self.tiles.iter().map(|t| t.grids.cell_bytes()).sum()
    }

    /// Finds `scan` in the map: in the prior's window when there is one (and nowhere else:
    /// see [`Self::relocalize`]), over the whole map when there is none.
    pub fn localize(
        &self,
        scan: &Scan2,
        prior: Option<&Prior>,
    ) -> Result<Localization, LocalizeError> {
        match prior {
            Some(prior) => self.search_window(scan, prior),
            None => self.search_global(scan),
        }
    }

    /// As [`Self::localize`], falling back to the global search when the prior's window holds
    /// no match, or an ambiguous one: a robot that is lost, or whose prior is wrong. A
    /// wrong prior beside a long wall finds the wall, shifted; the ambiguity test (a pose
    /// half the window away scoring nearly as well) sends it to the global search instead.
    pub fn relocalize(
        &self,
        scan: &Scan2,
        prior: Option<&Prior>,
    ) -> Result<Localization, LocalizeError> {
        match prior.map(|p| self.search_in(scan, p, true)) {
            Some(Ok(found)) => Ok(found),
            _ => self.search_global(scan),
        }
    }

    /// The best pose within the prior's window, refined. A robot followed by odometry needs
    /// no ambiguity test: its prior is what keeps it in place along a wall.
    pub fn search_window(
        &self,
        scan: &Scan2,
        prior: &Prior,
    ) -> Result<Localization, LocalizeError> {
        self.search_in(scan, prior, false)
    }

    fn search_in(
        &self,
        scan: &Scan2,
        prior: &Prior,
        unambiguous: bool,
    ) -> Result<Localization, LocalizeError> {
        let p = &self.params;
        let (x, y) = (prior.pose.x, prior.pose.y);
        let tile = tiles::nearest(&self.tiles, [x, y], p.tile_m)
            .ok_or(LocalizeError::OutsideMap { x, y })?;
        let window = SearchWindow {
            linear_m: prior.linear_m.max(p.grid.resolution_m),
            angular_rad: prior.angular_rad.max(0.0),
        };
        self.check_returns(scan)?;
        let not_found = LocalizeError::NotFound {
            min_score: p.min_score,
            best: None,
        };
        let found = search(&tile.grids, scan, prior.pose, &window, p.min_score, &p.grid)
            .ok_or(not_found)?;
        if unambiguous {
            let excluded = Exclusion {
                pose: found.pose,
                radius_m: p.ambiguity_radius_m.min(window.linear_m / 2.0),
            };
            let floor = found.score * p.max_runner_up_ratio;
            let grids = &tile.grids;
            let rival = runner_up(grids, scan, prior.pose, &window, &excluded, floor, &p.grid);
            let mut rivals: Vec<CorrelativeMatch> = rival.into_iter().collect();
            let verified =
                self.verified(scan, &found, &mut rivals, SearchKind::Window, p.min_score)?;
            if verified.quality < p.prior_min_quality {
                return Err(LocalizeError::NotFound {
                    min_score: p.min_score,
                    best: Some(found.score),
                });
            }
            return Ok(verified);
        }
        self.refined(scan, &found, SearchKind::Window, p.min_score)
    }

    /// The best pose anywhere in the map, at any heading, refined; refused when a pose
    /// elsewhere scores nearly as well.
    pub fn search_global(&self, scan: &Scan2) -> Result<Localization, LocalizeError> {
        let p = &self.params;
        self.check_returns(scan)?;
        let whole = SearchWindow {
            linear_m: p.tile_m / 2.0,
            angular_rad: std::f64::consts::PI,
        };
        // Each tile's best. A tile need only beat a share of the best so far: below it, it
        // is neither the best nor its rival.
        let mut bests: Vec<(usize, CorrelativeMatch)> = Vec::new();
        let mut floor = p.global_min_score;
        let mut candidates = 0;
        for (k, tile) in self.tiles.iter().enumerate() {
            if let Some(found) = search(&tile.grids, scan, tile.centre(), &whole, floor, &p.grid) {
                candidates += found.nodes;
                floor = floor.max(found.score * p.max_runner_up_ratio);
                bests.push((k, found));
            }
        }
        let Some(&(_, best)) = bests.iter().max_by(|a, b| a.1.score.total_cmp(&b.1.score)) else {
            return Err(LocalizeError::NotFound {
                min_score: p.global_min_score,
                best: None,
            });
        };
        // The rival: another tile's best, or the best of a tile away from the best pose.
        let rival_floor = best.score * p.max_runner_up_ratio;
        let excluded = Exclusion {
            pose: best.pose,
            radius_m: p.ambiguity_radius_m,
        };
        let far = |m: &CorrelativeMatch| distance(&m.pose, &best.pose) > p.ambiguity_radius_m;
        let mut rivals: Vec<CorrelativeMatch> = bests
            .iter()
            .filter_map(|(k, m)| {
                if far(m) {
                    return Some(*m);
                }
                let tile = &self.tiles[*k];
                let centre = tile.centre();
                runner_up(
                    &tile.grids,
                    scan,
                    centre,
                    &whole,
                    &excluded,
                    rival_floor,
                    &p.grid,
                )
                .filter(far)
            })
            .filter(|m| m.score >= rival_floor)
            .collect();
        let mut found = self.verified(
            scan,
            &best,
            &mut rivals,
            SearchKind::Global,
            p.global_min_score,
        )?;
        found.candidates = candidates;
        Ok(found)
    }

    /// `best` refined, unless one of `rivals` (poses elsewhere that score nearly as well)
    /// refines about as well: then the scan is ambiguous. The refinement sees what the
    /// correlative score does not: returns in space the map saw free. A wall that fits a
    /// shifted pose fits it with conflicts, and a rival that does not refine, or refines
    /// far worse, is no rival.
    fn verified(
        &self,
        scan: &Scan2,
        best: &CorrelativeMatch,
        rivals: &mut [CorrelativeMatch],
        kind: SearchKind,
        min_score: f64,
    ) -> Result<Localization, LocalizeError> {
        let p = &self.params;
        let found = self.refined(scan, best, kind, min_score)?;
        rivals.sort_by(|a, b| b.score.total_cmp(&a.score));
        for rival in rivals.iter().take(p.max_rivals_refined) {
            let Ok(other) = self.refined(scan, rival, kind, min_score) else {
                continue;
            };
            let apart = distance(&other.pose, &found.pose);
            if apart > p.ambiguity_radius_m.min(distance(&rival.pose, &best.pose))
                && other.quality >= found.quality - p.quality_margin
            {
                return Err(LocalizeError::Ambiguous {
                    score: best.score,
                    rival: rival.score,
                    distance_m: apart,
                });
            }
        }
        if rivals.len() > p.max_rivals_refined {
            let rival = rivals[p.max_rivals_refined];
            return Err(LocalizeError::Ambiguous {
                score: best.score,
                rival: rival.score,
                distance_m: distance(&rival.pose, &best.pose),
            });
        }
        Ok(found)
    }

    fn check_returns(&self, scan: &Scan2) -> Result<(), LocalizeError> {
        let range = self.params.grid.max_range_m;
        match scan.points().iter().any(|q| q[0].hypot(q[1]) <= range) {
            true => Ok(()),
            false => Err(LocalizeError::NoReturns(range)),
        }
    }

    /// The correlative pose refined against the map's nearest scans: IDC from it against
    /// the nearest, point-to-line against the nearest few, gated, and not far from it.
    fn refined(
        &self,
        scan: &Scan2,
        found: &CorrelativeMatch,
        kind: SearchKind,
        min_score: f64,
    ) -> Result<Localization, LocalizeError> {
        let p = &self.params;
        let not_found = LocalizeError::NotFound {
            min_score,
            best: Some(found.score),
        };
        let near = self
            .nodes
            .nearest(&self.scans, [found.pose.x, found.pose.y], p.reference_nodes);
        let Some(&first) = near.first() else {
            return Err(not_found);
        };
        let frame = self.scans[first].0;
        let guess = frame.between(&found.pose);
        let m = idc(&self.scans[first].1, scan, guess, &p.idc).map_err(|_| not_found.clone())?;
        let references: Vec<Reference> = near
            .iter()
            .map(|&k| Reference {
                scan: &self.scans[k].1,
                pose: frame.between(&self.scans[k].0),
            })
            .collect();
        let m = crate::matching::refine_against(&references, scan, &m, None, &p.idc, &p.refine)
            .map_err(|_| not_found.clone())?;
        let pose = frame.compose(&m.pose);
        let turn = wrap_angle(pose.theta - found.pose.theta).abs();
        let agrees =
            distance(&pose, &found.pose) <= p.refine_max_shift_m && turn <= p.refine_max_turn_rad;
        if !(agrees && accept(&m, &p.gate)) {
            return Err(not_found);
        }
        Ok(Localization {
            pose,
            covariance: rotated(&m.covariance, frame.theta),
            score: found.score,
            quality: m.quality,
            search: kind,
            reference: first,
            candidates: found.nodes,
        })
    }
}

fn distance(a: &Pose2, b: &Pose2) -> f64 {
    (a.x - b.x).hypot(a.y - b.y)
}

/// A covariance of (x, y, θ) in a frame turned by `theta`, in the outer frame: R C Rᵀ.
fn rotated(c: &[[f64; 3]; 3], theta: f64) -> [[f64; 3]; 3] {
    let (s, co) = theta.sin_cos();
    let r = nalgebra::Matrix3::new(co, -s, 0.0, s, co, 0.0, 0.0, 0.0, 1.0);
    let m = nalgebra::Matrix3::from_fn(|i, j| c[i][j]);
    let out = r * m * r.transpose();
    std::array::from_fn(|i| std::array::from_fn(|j| out[(i, j)]))
}
