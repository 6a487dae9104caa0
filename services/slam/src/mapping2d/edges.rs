//! The edges a new node brings: the odometry check of a sequential match, GPS edges, loop
//! closures, and the information matrices of odometry and matches.

use super::{GpsObservation, Mapper2d};
use crate::matching::{Match, accept, idc};
use crate::network::{GpsEdge, is_information};
use crate::se2::{Pose2, wrap_angle};
use nalgebra::Matrix3;

impl Mapper2d {
    /// Whether match `m` of two nodes of one chain agrees with their odometry `step` (see
    /// `match_odometry_max_chi2`).
    pub(super) fn agrees_with_odometry(&self, m: &Match, step: &Pose2) -> bool {
        let limit = self.params.match_odometry_max_chi2;
        if limit == f64::INFINITY {
            return true;
        }
        let Some(odometry) = self.odometry_information(step).try_inverse() else {
            return false;
        };
        let Some(matched) = self.match_information(&m.covariance).try_inverse() else {
            return false;
        };
        let e = nalgebra::Vector3::new(
            m.pose.x - step.x,
            m.pose.y - step.y,
            wrap_angle(m.pose.theta - step.theta),
        );
        (odometry + matched)
            .try_inverse()
            .is_some_and(|i| (e.transpose() * i * e)[(0, 0)] <= limit)
    }

    /// Adds a GPS edge per fix of `node`; returns whether it added any.
    pub(super) fn add_gps(&mut self, node: usize, gps: &[GpsObservation]) -> bool {
        let mut added = false;
        for fix in gps {
            added |= self.add_gps_edge(node, fix);
        }
        added
    }

    /// Adds the GPS edge of one fix of `node`; returns whether it was taken.
    fn add_gps_edge(&mut self, node: usize, fix: &GpsObservation) -> bool {
        let Some(edge) = self.gps_edge(node, fix) else {
            return false;
        };
        self.graph.gps.push(edge);
        self.stats.gps_edges += 1;
        true
    }

    /// The GPS edge of one fix of `node`. A fix the network would reject (NaN, a covariance
    /// not positive definite) is dropped here rather than failing every later optimization.
    pub(super) fn gps_edge(&self, node: usize, fix: &GpsObservation) -> Option<GpsEdge> {
        let information = fix.covariance_m2.try_inverse()?;
        let finite = fix
            .position_m
            .iter()
            .chain(fix.lever_arm_m.iter())
            .all(|v| v.is_finite());
        (is_information(&information) && finite).then_some(GpsEdge {
            node,
            position_m: fix.position_m,
            information,
            lever_arm_m: fix.lever_arm_m,
            robust: self.params.gps_robust,
        })
    }

    /// Matches `node` against earlier nodes near it, its own robot's and the others';
    /// returns how many edges the consistency check let through (this node's closures or
    /// earlier ones they support).
    pub(super) fn close_loops(&mut self, node: usize) -> usize {
        let p = self.params.clone();
        let here = self.graph.poses[node];
        let (robot, place) = self.node_robot[node];
        self.sync_parts();
        let parts = &self.parts;
        let shared_frame = |j: usize| !parts.may_meet(node, j);
        let distance = |j: usize| {
            let pose = &self.graph.poses[j];
            (pose.x - here.x).hypot(pose.y - here.y)
        };
        // Its own robot's earlier nodes, along its chain; the others' from the nodes filed
        // near it.
        let own = self.book.paths.chain_nodes(robot).iter().copied();
        let own = own.take_while(|&j| self.node_robot[j].1 + p.loop_min_node_gap <= place);
        let own = own.filter_map(|j| {
            let growth = p.loop_search_growth * (self.node_path_m[node] - self.node_path_m[j]);
            let d = distance(j);
            (d <= p.loop_search_radius_m + growth).then_some((d, j))
        });
        let radius = p.inter_robot_search_radius_m;
        let others = self.near.near(&here, radius).filter_map(|j| {
            // Another robot's estimate is comparable only in a shared frame: the same part,
            // or two parts both anchored by GPS.
            let d = distance(j);
            (j < node && self.node_robot[j].0 != robot && d <= radius && shared_frame(j))
                .then_some((d, j))
        });
        let mut candidates: Vec<(f64, usize)> = own.chain(others).collect();
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        // Spread the candidates along the chains: the nearest one, then others at least
        // loop_min_node_gap nodes from those taken on the same chain.
        let mut taken: Vec<usize> = Vec::new();
        for (_, j) in candidates {
            if taken.len() >= p.loop_max_candidates {
                break;
            }
            let (chain, at) = self.node_robot[j];
            if taken.iter().all(|&t| {
                let (c, a) = self.node_robot[t];
                c != chain || a.abs_diff(at) >= p.loop_min_node_gap
            }) {
                taken.push(j);
            }
        }
        let mut added = 0;
        for j in taken {
            self.stats.loop_candidates += 1;
            let guess = self.graph.poses[j].between(&here);
            let Ok(m) = idc(&self.node_scans[j], &self.node_scans[node], guess, &p.idc) else {
                continue;
            };
            if !accept(&m, &p.gate) {
                continue;
            }
            self.stats.loop_matches += 1;
            let information = self.match_information(&m.covariance);
            added += self.submit_and_verify(j, node, m.pose, information);
        }
        added
    }

    /// The odometry model's standard deviations of a step, (σ_xy m, σ_θ rad): they grow
    /// with its length and turn.
    pub(super) fn odometry_sigmas(&self, step: &Pose2) -> (f64, f64) {
        let p = &self.params;
        let sxy = p.odometry_sigma_xy_m + p.odometry_sigma_xy_per_m * step.x.hypot(step.y);
        let st = p.odometry_sigma_theta_rad
            + p.odometry_sigma_theta_per_rad * wrap_angle(step.theta).abs();
        (sxy, st)
    }

    /// Information of an odometry step (see [`Self::odometry_sigmas`]).
    pub(super) fn odometry_information(&self, step: &Pose2) -> Matrix3<f64> {
        let (sxy, st) = self.odometry_sigmas(step);
        Matrix3::from_diagonal(&nalgebra::Vector3::new(
            1.0 / (sxy * sxy),
            1.0 / (sxy * sxy),
            1.0 / (st * st),
        ))
    }

    /// Information of a scan match: its covariance with a floor on each standard deviation.
    pub(super) fn match_information(&self, covariance: &[[f64; 3]; 3]) -> Matrix3<f64> {
        let p = &self.params;
        let mut c = Matrix3::from_fn(|r, k| covariance[r][k]);
        c = (c + c.transpose()) * 0.5;
        let floor = [
            p.match_min_sigma_xy_m.powi(2),
            p.match_min_sigma_xy_m.powi(2),
            p.match_min_sigma_theta_rad.powi(2),
        ];
        for (d, f) in floor.iter().enumerate() {
            c[(d, d)] += f;
        }
        c.try_inverse()
            .filter(|i| i.iter().all(|v| v.is_finite()))
            .unwrap_or_else(|| {
                Matrix3::from_diagonal(&nalgebra::Vector3::new(
                    1.0 / floor[0],
                    1.0 / floor[1],
                    1.0 / floor[2],
                ))
            })
    }
}
