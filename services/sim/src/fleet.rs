//! A robot of a simulated fleet: it drives one of the park's loops, taking one yawing 3D
//! scan after another (scanning while driving, paper 2.1), with 3D dead reckoning, GPS, a
//! fixed 2D scanner for comparison, and ground truth. What an edge service's source yields.

use crate::rng::Rng;
use crate::robot::Route;
use crate::sensors::{Beam2d, DeadReckoning, FixedScanner2d, Gps, GpsFix, SimScan, YawingScanner};
use crate::world::World;
use leveling::{PoseTrack, TimedPose};
use nalgebra::Isometry3;

/// One 3D scan of a fleet robot with everything measured around it.
#[derive(Clone, Debug)]
pub struct FleetScan {
    /// The robot's index in the fleet.
    pub robot: usize,
    /// Scans of this robot so far, from 0.
    pub seq: u64,
    /// The 3D scan (sensor frame) and its ground truth.
    pub scan: SimScan,
    /// Dead reckoning covering the scan's columns, in the robot's odometry frame.
    pub track: PoseTrack,
    /// The dead-reckoning pose at the scan's first column (odometry frame).
    pub odometry_at_start: Isometry3<f64>,
    /// The GPS fix of the receiver period in which the scan starts; `None` on a dropout.
    pub gps: Option<GpsFix>,
    /// Every fix after the previous scan's start up to this scan's start (for the first scan,
    /// up to its start), oldest first: at 1 Hz and a scan every 4 s, four (fewer on dropouts).
    /// Ends with `gps` when that is `Some`.
    pub gps_since_previous: Vec<GpsFix>,
    /// The fixed horizontal 2D scanner's scan at the scan's start (for comparison).
    pub fixed2d: Vec<Beam2d>,
}

/// Where a fleet robot starts, and so what its odometry frame is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FleetStart {
    /// At its loop's start, with odometry in the world frame, as from a known dock.
    #[default]
    Dock,
    /// At a random place along its loop (drawn from the seed), with odometry starting at
    /// the identity: the mapper does not know where the robot is.
    Scattered,
}

/// A robot of the simulated fleet, yielding its scans in time order.
pub struct FleetRobot<'w> {
    index: usize,
    world: &'w World,
    route: Route,
    scanner: YawingScanner,
    fixed2d: FixedScanner2d,
    gps: Gps,
    odometry: Vec<TimedPose>,
    fixes: Vec<GpsFix>,
    rng: Rng,
    next_start_ns: u64,
    previous_start_ns: Option<u64>,
    seq: u64,
    end_ns: u64,
}

impl<'w> FleetRobot<'w> {
    /// Robot `index` (0, 1 or 2: the park's loops) driving for `duration_ns` from time 0,
    /// with its own random draws from `seed`. `None` for an index without a loop.
    pub fn new(world: &'w World, index: usize, duration_ns: u64, seed: u64) -> Option<Self> {
        FleetRobot::starting(world, index, duration_ns, seed, FleetStart::Dock)
    }

    /// As [`FleetRobot::new`], starting as `start` says.
    pub fn starting(
        world: &'w World,
        index: usize,
        duration_ns: u64,
        seed: u64,
        start: FleetStart,
    ) -> Option<Self> {
        let mut route = Route::park_loop(index)?;
        let scanner = YawingScanner::default();
        let mut rng = Rng::new(seed ^ (0x9e37_79b9_7f4a_7c15u64.wrapping_mul(index as u64 + 1)));
        if start == FleetStart::Scattered {
            // Its own draw, so the sensors' noise is the same as from the dock.
            let mut draw = Rng::new(seed ^ 0x5ca7_7e25 ^ index as u64);
            let start_m = draw.uniform() * route.length_m();
            route = route.starting_at(start_m);
        }
        // Sensors cover a whole scan beyond the end, so the last scan is complete.
        let horizon = duration_ns + scanner.end_stamp_ns(0) + 1_000_000_000;
        let gps = Gps::default();
        let (mut odometry, fixes) = {
            let truth = route.truth(world);
            let odometry = DeadReckoning::default().track(&truth, 0, horizon, &mut rng);
            (odometry, gps.fixes(&truth, 0, horizon, &mut rng))
        };
        if start == FleetStart::Scattered {
            // The odometry frame: the start's horizontal position and heading (level, so
            // roll and pitch stay the ground's).
            let (p, yaw) = route.planar_at(0);
            let frame = Isometry3::new(
                nalgebra::Vector3::new(p.x, p.y, 0.0),
                nalgebra::Vector3::z() * yaw,
            );
            for sample in &mut odometry {
                sample.pose = frame.inverse() * sample.pose;
            }
        }
        Some(FleetRobot {
            index,
            world,
            route,
            scanner,
            fixed2d: FixedScanner2d::default(),
            gps,
            odometry,
            fixes,
            rng,
            next_start_ns: 0,
            previous_start_ns: None,
            seq: 0,
            end_ns: duration_ns,
        })
    }

    /// The robot's yawing 3D scanner.
    pub fn scanner(&self) -> &YawingScanner {
        &self.scanner
    }

    /// The robot's GPS receiver.
    pub fn gps(&self) -> &Gps {
        &self.gps
    }

    /// The fixed horizontal 2D scanner it carries for the baseline.
    pub fn fixed_scanner(&self) -> &FixedScanner2d {
        &self.fixed2d
    }

    /// How long it drives (ns from time 0).
    pub fn duration_ns(&self) -> u64 {
        self.end_ns
    }

    /// The robot's true pose (robot frame in the world frame) at a time.
    pub fn truth_at(&self, stamp_ns: u64) -> Isometry3<f64> {
        self.route.pose_at(self.world, stamp_ns)
    }

    /// Dead reckoning (odometry frame) from `from_ns` to `to_ns`, with a sample either side
    /// so that it covers both ends.
    ///
    /// # Panics
    /// Beyond the duration given to [`FleetRobot::new`] plus one scan.
    pub fn odometry_track(&self, from_ns: u64, to_ns: u64) -> PoseTrack {
        let lo = self
            .odometry
            .partition_point(|p| p.stamp_ns <= from_ns)
            .saturating_sub(1);
        let hi =
            (self.odometry.partition_point(|p| p.stamp_ns < to_ns) + 1).min(self.odometry.len());
        let track = PoseTrack::new(self.odometry[lo..hi].to_vec()).expect("ordered samples");
        assert!(
            track.at(to_ns).is_some(),
            "dead reckoning ends before {to_ns} ns"
        );
        track
    }

    /// The next scan, or `None` once the next one would start after the duration.
    pub fn next_scan(&mut self) -> Option<FleetScan> {
        let start = self.next_start_ns;
        if start > self.end_ns {
            return None;
        }
        let end = self.scanner.end_stamp_ns(start);
        let truth = self.route.truth(self.world);
        let scan = self.scanner.scan(self.world, &truth, start, &mut self.rng);
        let track = self.odometry_track(start, end);
        let odometry_at_start = track.at(start).expect("the track covers the scan");
        let gps = self
            .fixes
            .iter()
            .take_while(|f| f.stamp_ns <= start)
            .last()
            .filter(|f| f.stamp_ns + self.gps.period_ns > start)
            .copied();
        let gps_since_previous = self
            .fixes
            .iter()
            .skip_while(|f| self.previous_start_ns.is_some_and(|p| f.stamp_ns <= p))
            .take_while(|f| f.stamp_ns <= start)
            .copied()
            .collect();
        let fixed2d = self.fixed2d.scan(self.world, &truth(start));
        self.previous_start_ns = Some(start);
        self.next_start_ns = end + 1;
        let seq = self.seq;
        self.seq += 1;
        Some(FleetScan {
            robot: self.index,
            seq,
            scan,
            track,
            odometry_at_start,
            gps,
            gps_since_previous,
            fixed2d,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_fix_comes_with_one_scan_the_latest_as_gps() {
        let world = World::park();
        let mut robot = FleetRobot::new(&world, 1, 40_000_000_000, 3).unwrap();
        let (mut taken, mut previous_start) = (Vec::new(), None);
        while let Some(scan) = robot.next_scan() {
            let start = scan.scan.raw.columns[0].stamp_ns;
            for fix in &scan.gps_since_previous {
                assert!(fix.stamp_ns <= start);
                assert!(previous_start.is_none_or(|p| fix.stamp_ns > p));
            }
            if scan.gps.is_some() {
                assert_eq!(scan.gps, scan.gps_since_previous.last().copied());
            }
            assert!(scan.seq == 0 || scan.gps_since_previous.len() >= 3);
            taken.extend(scan.gps_since_previous);
            previous_start = Some(start);
        }
        let before_last_start: Vec<GpsFix> = robot
            .fixes
            .iter()
            .take_while(|f| previous_start.is_some_and(|p| f.stamp_ns <= p))
            .copied()
            .collect();
        assert_eq!(taken, before_last_start);
    }
}
