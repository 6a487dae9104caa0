//! Simulated sensors, each measuring the world from the robot's true motion.
//!
//! - [`YawingScanner`]: the paper's 3D scanner (a vertical 2D scanner turned about the upright
//!   axis); every column is measured from the robot's true pose at the column's own time.
//! - [`FixedScanner2d`]: a horizontal 2D laser fixed to the chassis (tilts with the robot).
//! - [`DeadReckoning`]: gyro + wheel encoders, inclinometer-aided attitude.
//! - [`Gps`]: 1 Hz fixes with noise, dropouts and multipath jumps.

mod dead_reckoning;
mod fixed2d;
mod gps;
mod yawing;

pub use dead_reckoning::DeadReckoning;
pub use fixed2d::{Beam2d, FixedScanner2d};
pub use gps::{Gps, GpsFix};
pub use yawing::{SimScan, YawingScanner};
