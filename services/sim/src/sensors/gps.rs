//! GPS fixes in the local ENU frame, with noise, dropouts and multipath jumps.

use crate::geodesy::{GeoDatum, Geodetic, PARK_DATUM};
use crate::rng::Rng;
use nalgebra::{Isometry3, Point3, Vector3};

/// A GPS receiver on the robot.
///
/// The world frame is the local ENU frame of `datum`. Each fix is the antenna's true position
/// plus Gaussian noise; with `dropout_probability` a second yields no fix; with
/// `multipath_probability` a multipath episode starts: a jump of `multipath_jump_m` metres
/// in a random horizontal direction that lasts `multipath_fixes` fixes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gps {
    /// Time between fixes (ns).
    pub period_ns: u64,
    /// Standard deviation of each horizontal axis (m).
    pub sigma_horizontal_m: f64,
    /// Standard deviation of the height (m).
    pub sigma_vertical_m: f64,
    /// Probability per fix time that there is no fix.
    pub dropout_probability: f64,
    /// Probability per fix that a multipath episode starts.
    pub multipath_probability: f64,
    /// Size of a multipath jump, lower and upper bound (m).
    pub multipath_jump_m: [f64; 2],
    /// Length of a multipath episode in fixes, lower and upper bound.
    pub multipath_fixes: [u32; 2],
    /// The antenna in the robot frame (m).
    pub antenna_in_robot_m: Vector3<f64>,
    /// The datum of the local ENU frame.
    pub datum: GeoDatum,
}

impl Default for Gps {
    /// A plain (non-RTK) receiver at 1 Hz: σ 0.5 m horizontal, 1 m vertical, 2 % dropouts,
    /// multipath episodes of 3–8 m lasting 2–5 fixes starting at 2 % of fixes.
    fn default() -> Self {
        Gps {
            period_ns: 1_000_000_000,
            sigma_horizontal_m: 0.5,
            sigma_vertical_m: 1.0,
            dropout_probability: 0.02,
            multipath_probability: 0.02,
            multipath_jump_m: [3.0, 8.0],
            multipath_fixes: [2, 5],
            antenna_in_robot_m: Vector3::new(0.0, 0.0, 1.0),
            datum: PARK_DATUM,
        }
    }
}

/// One GPS fix with its ground truth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpsFix {
    /// Time of the fix (ns, the simulation clock).
    pub stamp_ns: u64,
    /// Measured antenna position in the local ENU frame (m).
    pub enu_m: Point3<f64>,
    /// The receiver's claimed standard deviations, horizontal and vertical (m).
    pub sigma_horizontal_m: f64,
    /// See `sigma_horizontal_m`.
    pub sigma_vertical_m: f64,
    /// Ground truth: where the antenna really was (m, ENU).
    pub true_enu_m: Point3<f64>,
    /// Ground truth: this fix is a multipath outlier.
    pub multipath: bool,
}

impl GpsFix {
    /// The measured position in WGS84.
    pub fn geodetic(&self, datum: &GeoDatum) -> Geodetic {
        datum.enu_to_geodetic(&self.enu_m.coords)
    }
}

impl Gps {
    /// Fixes at `start_ns`, `start_ns + period`, … up to `end_ns`, from the robot moving
    /// along `truth`.
    pub fn fixes(
        &self,
        truth: &impl Fn(u64) -> Isometry3<f64>,
        start_ns: u64,
        end_ns: u64,
        rng: &mut Rng,
    ) -> Vec<GpsFix> {
        let mut fixes = Vec::new();
        let mut jump: Option<(Vector3<f64>, u32)> = None;
        let mut stamp = start_ns;
        while stamp <= end_ns {
            let antenna = truth(stamp) * Point3::from(self.antenna_in_robot_m);
            if jump.is_none() && rng.chance(self.multipath_probability) {
                let [lo, hi] = self.multipath_jump_m;
                let size = rng.range(lo, hi);
                let a = rng.range(0.0, std::f64::consts::TAU);
                let [n_lo, n_hi] = self.multipath_fixes;
                let fixes = n_lo + rng.below((n_hi.saturating_sub(n_lo) + 1) as u64) as u32;
                jump = Some((
                    Vector3::new(size * a.cos(), size * a.sin(), 0.0),
                    fixes.max(1),
                ));
            }
            let noise = Vector3::new(
                rng.gauss(self.sigma_horizontal_m),
                rng.gauss(self.sigma_horizontal_m),
                rng.gauss(self.sigma_vertical_m),
            );
            let offset = jump.map_or(Vector3::zeros(), |(v, _)| v);
            let multipath = jump.is_some();
            jump = jump.and_then(|(v, left)| (left > 1).then_some((v, left - 1)));
            if !rng.chance(self.dropout_probability) {
                fixes.push(GpsFix {
                    stamp_ns: stamp,
                    enu_m: antenna + offset + noise,
                    sigma_horizontal_m: self.sigma_horizontal_m,
                    sigma_vertical_m: self.sigma_vertical_m,
                    true_enu_m: antenna,
                    multipath,
                });
            }
            stamp += self.period_ns.max(1);
        }
        fixes
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::Route;
    use crate::world::World;

    #[test]
    fn noise_dropouts_and_multipath_as_configured() {
        let world = World::park();
        let route = Route::park_loop(0).unwrap();
        let gps = Gps {
            dropout_probability: 0.05,
            multipath_probability: 0.03,
            ..Default::default()
        };
        let n = 3_000u64;
        let fixes = gps.fixes(
            &route.truth(&world),
            0,
            (n - 1) * 1_000_000_000,
            &mut Rng::new(11),
        );
        let dropped = n as usize - fixes.len();
        assert!((100..200).contains(&dropped), "dropped {dropped}");
        let (clean, outliers): (Vec<&GpsFix>, Vec<&GpsFix>) =
            fixes.iter().partition(|f| !f.multipath);
        let err2: f64 = clean
            .iter()
            .map(|f| (f.enu_m - f.true_enu_m).xy().norm_squared())
            .sum();
        let sigma = (err2 / (2.0 * clean.len() as f64)).sqrt();
        assert!((sigma - 0.5).abs() < 0.03, "σ {sigma}");
        assert!(outliers.len() > 100, "{} multipath fixes", outliers.len());
        for f in &outliers {
            let e = (f.enu_m - f.true_enu_m).xy().norm();
            assert!(e > 1.0 && e < 10.0, "jump {e}");
        }
        // Episodes last several fixes.
        let runs = fixes
            .windows(2)
            .filter(|w| w[0].multipath && !w[1].multipath)
            .count();
        assert!(outliers.len() as f64 / runs as f64 > 2.0);
        let g = fixes[0].geodetic(&gps.datum);
        assert!((g.latitude_deg - 52.39).abs() < 0.001 && (g.longitude_deg - 9.71).abs() < 0.002);
    }
}
