//! [`Mapper2dParams`]: every tunable of the 2D mapper, and the preset for precise dead
//! reckoning.

use crate::matching::{IdcParams, QualityGate};
use crate::optimize::OptimizeParams;
use crate::robust::Robust;
use serde::{Deserialize, Serialize};

/// Tunables of the 2D mapper, each with its unit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
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
    /// Do not optimize while adding scans; the caller runs
    /// [`Mapper2d::optimize_pending`](super::Mapper2d::optimize_pending) (a server batching
    /// the nodes that arrived together into one solve).
    pub defer_optimization: bool,
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
    /// Candidates on another robot's chain: within this distance (m) of the new node.
    pub inter_robot_search_radius_m: f64,
    /// Robust kernel of GPS edges (multipath jumps).
    pub gps_robust: Robust,
    /// Scan matching (IDC) of successive nodes and loop-closure candidates.
    pub idc: IdcParams,
    /// The quality gate a match must pass to become an edge.
    pub gate: QualityGate,
    /// The nonlinear optimization of the network.
    pub optimize: OptimizeParams,
    /// Loop closure by correlative search against submaps.
    pub submaps: super::SubmapSearchParams,
    /// A lone robot (no GPS, no closure with another) looked for in the others' submaps.
    pub first_contact: super::FirstContactParams,
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
            defer_optimization: false,
            loop_search_radius_m: 3.0,
            loop_search_growth: 0.2,
            loop_min_node_gap: 20,
            loop_max_candidates: 4,
            loop_robust: Robust::Cauchy { c: 10.0 },
            inter_robot_search_radius_m: 3.0,
            gps_robust: Robust::Cauchy { c: 2.0 },
            idc: IdcParams::default(),
            gate: QualityGate::default(),
            optimize: OptimizeParams::default(),
            submaps: super::SubmapSearchParams::default(),
            first_contact: super::FirstContactParams::default(),
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
            idc: crate::matching::IdcParams {
                min_correspondences: 10,
                ..defaults.idc.clone()
            },
            ..defaults
        }
    }
}
