//! [`Mapper2dParams`]: every tunable of the 2D mapper, and the preset for precise dead
//! reckoning.

use crate::matching::{IdcParams, QualityGate, RefineParams};
use crate::optimize::OptimizeParams;
use crate::robust::Robust;
use serde::{Deserialize, Serialize};

/// Tunables of the 2D mapper, each with its unit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Mapper2dParams {
    /// A new node after this much travel (m)…
    pub node_distance_m: f64,
    /// …or this much rotation (rad).
    pub node_rotation_rad: f64,
    /// Odometry noise per step: σ_xy = a + b·distance (m), σ_θ = c + d·|rotation| (rad).
    pub odometry_sigma_xy_m: f64,
    /// See `odometry_sigma_xy_m` (m per m travelled).
    pub odometry_sigma_xy_per_m: f64,
    /// See `odometry_sigma_xy_m` (rad).
    pub odometry_sigma_theta_rad: f64,
    /// See `odometry_sigma_xy_m` (rad per rad turned).
    pub odometry_sigma_theta_per_rad: f64,
    /// Floor on the standard deviations taken from a scan match (m, rad): IDC's covariance
    /// is optimistic on clean data.
    pub match_min_sigma_xy_m: f64,
    /// See `match_min_sigma_xy_m` (rad).
    pub match_min_sigma_theta_rad: f64,
    /// A match between nodes of one chain is rejected when it disagrees with odometry: the
    /// squared Mahalanobis distance between the two (odometry and match covariances
    /// summed) above this. Infinite: no check.
    pub match_odometry_max_chi2: f64,
    /// Keep the odometry edge beside an accepted match between successive nodes (odometry
    /// and scan matching fused), rather than the match alone.
    pub fuse_odometry: bool,
    /// When IDC's match with the last node fails the gate (a wrong minimum from a poor
    /// guess, or none), search the scan again by the correlative matcher on the local map
    /// over the odometry's 99.9 % window (docs/slam.md, "Point-to-line refinement"). Default
    /// true; off where odometry is trusted to arbitrate matches
    /// ([`Self::precise_dead_reckoning`]): it then errs less than a grid cell, and the node
    /// is left on it.
    pub sequential_search: bool,
    /// Do not optimize the whole network while adding scans: the caller runs
    /// [`Mapper2d::optimize_pending`](super::Mapper2d::optimize_pending) (a server batching
    /// the nodes that arrived together into one solve), or takes the solve to run in the
    /// background ([`Mapper2d::take_solve`](super::Mapper2d::take_solve)). Meanwhile each
    /// node that brings a closure or a fix re-solves a window of its chain at once
    /// (`local_window_nodes`).
    pub defer_optimization: bool,
    /// With `defer_optimization`: the newest nodes of a chain re-solved at a node that
    /// brings a closure or a fix, every other node held (0: none).
    pub local_window_nodes: usize,
    /// Loop-closure candidates: earlier nodes within this distance (m) of the new node, plus
    /// `loop_search_growth` times the path travelled between them (drift grows with it)…
    pub loop_search_radius_m: f64,
    /// See `loop_search_radius_m` (m per m of path).
    pub loop_search_growth: f64,
    /// …and at least this many nodes back.
    pub loop_min_node_gap: usize,
    /// At most this many candidates are matched per new node (the nearest first).
    pub loop_max_candidates: usize,
    /// Robust kernel of loop closures (within and between robots).
    pub loop_robust: Robust,
    /// The pairwise consistency check a loop closure must pass before it becomes an edge.
    pub loop_consistency: ConsistencyParams,
    /// Candidates on another robot's chain: within this distance (m) of the new node.
    pub inter_robot_search_radius_m: f64,
    /// Robust kernel of GPS edges (multipath jumps).
    pub gps_robust: Robust,
    /// Scan matching (IDC) of successive nodes and loop-closure candidates.
    pub idc: IdcParams,
    /// The point-to-line refinement of sequential matches and of the offsets of scans that
    /// hang off a node.
    pub refine: RefineParams,
    /// The quality gate a match must pass to become an edge.
    pub gate: QualityGate,
    /// The nonlinear optimization of the network.
    pub optimize: OptimizeParams,
    /// Loop closure by correlative search against submaps.
    pub submaps: super::SubmapSearchParams,
    /// Loop closure by a global search: every finished submap in the others, whole.
    pub global_search: super::GlobalSearchParams,
    /// A lone robot (no GPS, no closure with another) looked for in the others' submaps.
    pub first_contact: super::FirstContactParams,
    /// Bounded growth: when a place counts as covered (the fleet's map passes over it).
    pub coverage: super::CoverageParams,
}

impl Default for Mapper2dParams {
    fn default() -> Self {
        Mapper2dParams {
            node_distance_m: 0.5,
            node_rotation_rad: 20f64.to_radians(),
            odometry_sigma_xy_m: 0.02,
            odometry_sigma_xy_per_m: 0.1,
            odometry_sigma_theta_rad: 1f64.to_radians(),
            odometry_sigma_theta_per_rad: 0.1,
            match_min_sigma_xy_m: 0.01,
            match_min_sigma_theta_rad: 0.2f64.to_radians(),
            match_odometry_max_chi2: f64::INFINITY,
            fuse_odometry: false,
            sequential_search: true,
            defer_optimization: false,
            local_window_nodes: 30,
            loop_search_radius_m: 3.0,
            loop_search_growth: 0.2,
            loop_min_node_gap: 20,
            loop_max_candidates: 4,
            loop_robust: Robust::Cauchy { c: 10.0 },
            loop_consistency: ConsistencyParams::default(),
            inter_robot_search_radius_m: 3.0,
            gps_robust: Robust::Cauchy { c: 2.0 },
            idc: IdcParams::default(),
            refine: RefineParams::default(),
            gate: QualityGate::default(),
            optimize: OptimizeParams::default(),
            submaps: super::SubmapSearchParams::default(),
            global_search: super::GlobalSearchParams::default(),
            first_contact: super::FirstContactParams::default(),
            coverage: super::CoverageParams::default(),
        }
    }
}

impl Mapper2dParams {
    /// For robots with precise dead reckoning (a fibre-optic-class gyro, bias ~10°/h, and
    /// wheels with 0.5 % scale error, as the simulator's `DeadReckoning::default()`), which
    /// errs by 0.001–0.04 m and about 0.01° over 5 m, and sparse leveled scans of open
    /// ground (a few dozen returns): odometry is then no worse than a sparse match, so a
    /// match that contradicts it is rejected and an accepted one is fused with it. Measured
    /// in `services/sim/tests/fleet_mapping.rs` and used by `levelmap demo`.
    pub fn precise_dead_reckoning() -> Mapper2dParams {
        let defaults = Mapper2dParams::default();
        Mapper2dParams {
            odometry_sigma_xy_m: 0.01,
            odometry_sigma_xy_per_m: 0.01,
            odometry_sigma_theta_rad: 0.002,
            odometry_sigma_theta_per_rad: 0.01,
            match_odometry_max_chi2: 16.0,
            fuse_odometry: true,
            sequential_search: false,
            // Off for now: on the simulated fleet it rejects the fixed 2D scanner's two wrong
            // closures, and the demo's comparison (leveled ≥ 3× better) no longer holds
            // (docs/measurements/slam.md, "Consistency of loop closures").
            loop_consistency: ConsistencyParams {
                enabled: false,
                ..ConsistencyParams::default()
            },
            idc: crate::matching::IdcParams {
                min_correspondences: 10,
                ..defaults.idc.clone()
            },
            ..defaults
        }
    }
}

/// Tunables of the loop closures' pairwise consistency check (PCM, see [`super::consistency`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ConsistencyParams {
    /// Off: every closure the quality gate accepts becomes an edge at once.
    pub enabled: bool,
    /// Two closures are consistent when the cycle they form with the chains between their
    /// ends has a squared Mahalanobis distance at most this (3 degrees of freedom).
    pub max_chi2: f64,
    /// Closures are compared when both their ends are at most this many nodes apart along
    /// their chains; a closure waits this many nodes of its chain for support.
    pub window_nodes: usize,
    /// A closure becomes an edge once it belongs to a maximum consistent set of at least this
    /// many closures (1: every closure no larger set contradicts).
    pub min_group: usize,
    /// A closure whose squared Mahalanobis distance from the current estimate (with its
    /// covariance and the floors below) is at most this needs no support: it hardly moves the
    /// map. It is still held back while a larger consistent set contradicts it.
    pub agree_max_chi2: f64,
    /// A closure that finds no support at once seeks it: the nodes this many places before
    /// and after its older end are matched against its newer end, from the pose it predicts,
    /// and those matches join the candidates (0: no such matches).
    pub support_offset_nodes: usize,
    /// Floors added to each sequential step's standard deviations (m, rad): matches between
    /// successive nodes are more precise in their covariance than in fact.
    pub step_min_sigma_xy_m: f64,
    /// See `step_min_sigma_xy_m` (rad).
    pub step_min_sigma_theta_rad: f64,
    /// Floors added to a closure's standard deviations (m, rad).
    pub closure_min_sigma_xy_m: f64,
    /// See `closure_min_sigma_xy_m` (rad).
    pub closure_min_sigma_theta_rad: f64,
}

impl Default for ConsistencyParams {
    fn default() -> Self {
        ConsistencyParams {
            enabled: true,
            max_chi2: 11.34,
            window_nodes: 25,
            min_group: 2,
            agree_max_chi2: 11.34,
            support_offset_nodes: 3,
            step_min_sigma_xy_m: 0.02,
            step_min_sigma_theta_rad: 0.5f64.to_radians(),
            closure_min_sigma_xy_m: 0.05,
            closure_min_sigma_theta_rad: 1f64.to_radians(),
        }
    }
}
