//! 3D dead reckoning: gyro and wheel encoders, attitude aided by an inclinometer.

use crate::rng::Rng;
use leveling::TimedPose;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// Simulated 3D dead reckoning sampled from the true motion.
///
/// Per step, the gyro measures the true body rates plus a constant bias (drawn per track)
/// and white noise; the wheel encoders measure the distance driven along the robot's x axis
/// with a scale error (drawn per track) and noise proportional to the distance. Roll and
/// pitch are pulled towards an inclinometer's reading (a complementary filter), so they stay
/// gravity-referenced; heading and position drift slowly, as odometry does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeadReckoning {
    /// Sampling rate (Hz).
    pub rate_hz: f64,
    /// White noise of each gyro axis per sample (rad/s, standard deviation).
    pub gyro_noise_rad_per_s: f64,
    /// Standard deviation of each gyro axis' constant bias (rad/s).
    pub gyro_bias_rad_per_s: f64,
    /// Standard deviation of the wheel scale error (fraction of the distance).
    pub wheel_scale_error: f64,
    /// Standard deviation of the wheel noise per sample, as a fraction of the step's distance.
    pub wheel_noise: f64,
    /// Noise of the inclinometer's roll and pitch (rad, standard deviation).
    pub inclinometer_noise_rad: f64,
    /// Weight of the inclinometer per sample (0: gyro only, 1: inclinometer only).
    pub inclinometer_gain: f64,
}

impl Default for DeadReckoning {
    /// A fibre-optic-class gyro (bias ~10°/h) and ordinary wheel encoders (0.5 % scale).
    fn default() -> Self {
        DeadReckoning {
            rate_hz: 100.0,
            gyro_noise_rad_per_s: 1e-3,
            gyro_bias_rad_per_s: 5e-5,
            wheel_scale_error: 0.005,
            wheel_noise: 0.01,
            inclinometer_noise_rad: 0.2f64.to_radians(),
            inclinometer_gain: 0.02,
        }
    }
}

impl DeadReckoning {
    /// The odometry track from `start_ns` to at least `end_ns`, one sample per period, in an
    /// odometry frame that coincides with the world frame at `start_ns` (the first sample is
    /// the true pose). `truth` gives the robot's true pose at a time.
    pub fn track(
        &self,
        truth: &impl Fn(u64) -> Isometry3<f64>,
        start_ns: u64,
        end_ns: u64,
        rng: &mut Rng,
    ) -> Vec<TimedPose> {
        let period_ns = ((1e9 / self.rate_hz).round() as u64).max(1);
        let dt = period_ns as f64 * 1e-9;
        let steps = end_ns.saturating_sub(start_ns).div_ceil(period_ns);
        let bias = Vector3::from_fn(|_, _| rng.gauss(self.gyro_bias_rad_per_s));
        let scale = 1.0 + rng.gauss(self.wheel_scale_error);

        let mut true_prev = truth(start_ns);
        let mut pose = true_prev;
        let mut track = Vec::with_capacity(steps as usize + 1);
        track.push(TimedPose {
            stamp_ns: start_ns,
            pose,
        });
        for k in 1..=steps {
            let stamp = start_ns + k * period_ns;
            let true_now = truth(stamp);
            // Gyro: the body rotation over the step, as a rate, plus bias and noise.
            let delta = true_prev.rotation.inverse() * true_now.rotation;
            let noise = Vector3::from_fn(|_, _| rng.gauss(self.gyro_noise_rad_per_s));
            let rate = delta.scaled_axis() / dt + bias + noise;
            let mut rotation = pose.rotation * UnitQuaternion::from_scaled_axis(rate * dt);
            // Inclinometer: roll and pitch towards gravity's, heading untouched.
            let (roll, pitch, yaw) = rotation.euler_angles();
            let (true_roll, true_pitch, _) = true_now.rotation.euler_angles();
            let g = self.inclinometer_gain;
            let measured_roll = true_roll + rng.gauss(self.inclinometer_noise_rad);
            let measured_pitch = true_pitch + rng.gauss(self.inclinometer_noise_rad);
            rotation = UnitQuaternion::from_euler_angles(
                roll + g * (measured_roll - roll),
                pitch + g * (measured_pitch - pitch),
                yaw,
            );
            // Wheels: the distance along the robot's x axis, scaled and noisy.
            let moved = true_prev.rotation.inverse()
                * (true_now.translation.vector - true_prev.translation.vector);
            let distance = moved.x * scale + rng.gauss(self.wheel_noise * moved.x.abs());
            let heading = pose.rotation.slerp(&rotation, 0.5);
            let translation = pose.translation.vector + heading * Vector3::new(distance, 0.0, 0.0);
            pose = Isometry3::from_parts(Translation3::from(translation), rotation);
            track.push(TimedPose {
                stamp_ns: stamp,
                pose,
            });
            true_prev = true_now;
        }
        track
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::Route;
    use crate::world::World;
    use leveling::heading_rad;

    #[test]
    fn drifts_slowly_and_keeps_attitude_gravity_referenced() {
        let world = World::park();
        let route = Route::park_loop(1).unwrap();
        let truth = route.truth(&world);
        let track = DeadReckoning::default().track(&truth, 0, 120_000_000_000, &mut Rng::new(3));
        assert_eq!(track.len(), 12_001);
        assert!(track.windows(2).all(|w| w[1].stamp_ns > w[0].stamp_ns));
        assert_eq!(track[0].pose, truth(0));
        let mut max_tilt_error = 0.0f64;
        for s in track.iter().step_by(100) {
            let t = truth(s.stamp_ns);
            let (r, p, _) = s.pose.rotation.euler_angles();
            let (tr, tp, _) = t.rotation.euler_angles();
            max_tilt_error = max_tilt_error.max((r - tr).abs()).max((p - tp).abs());
        }
        // Over the hills for two minutes, tilt stays within a fraction of a degree.
        assert!(
            max_tilt_error.to_degrees() < 0.5,
            "tilt error {}°",
            max_tilt_error.to_degrees()
        );
        // Locally accurate: over 4 s the relative motion is right to a few centimetres.
        for w in track.windows(401).step_by(1000) {
            let (a, b) = (&w[0], &w[400]);
            let odo = a.pose.inverse() * b.pose;
            let tru = truth(a.stamp_ns).inverse() * truth(b.stamp_ns);
            let err = (odo.translation.vector - tru.translation.vector).norm();
            assert!(err < 0.06, "relative error {err} m over 4 s");
        }
        // Globally it drifts, but slowly.
        let last = track.last().unwrap();
        let drift = (last.pose.translation.vector - truth(last.stamp_ns).translation.vector).norm();
        assert!(drift < 3.0, "drift {drift} m after 168 m");
        let yaw_err =
            heading_rad(&last.pose.rotation) - heading_rad(&truth(last.stamp_ns).rotation);
        assert!(yaw_err.abs().to_degrees() < 2.0);
    }

    #[test]
    fn a_standing_robot_stays_put() {
        let world = World::park();
        let pose = crate::robot::RobotBody::default().pose_on(&world, -20.0, 5.0, 1.0);
        let track = DeadReckoning::default().track(&|_| pose, 5, 4_000_000_005, &mut Rng::new(9));
        assert!(track.last().unwrap().stamp_ns >= 4_000_000_005);
        for s in &track {
            assert!((s.pose.translation.vector - pose.translation.vector).norm() < 1e-9);
            assert!(s.pose.rotation.angle_to(&pose.rotation) < 0.2f64.to_radians());
        }
    }
}
