//! The global loop search on the log it was built for: fr-clinic, a hospital the robot
//! crosses for 80 minutes and ends where it started. Its last, largest loop is 64 m from
//! closing on the estimate, beyond every local search's window. No relations are shipped
//! for it, so the loop is checked where the run ends: the last scan matched against the
//! first from where the map puts it must need only a small correction (before the global
//! search, the two scans lay 64 m apart and did not match at all). Wrong closures
//! injected (10 % of the clean run's closures) must not open the loop again.

mod common;

use common::map_injecting;
use graphio::carmen;
use slam::matching::metric::{ReturnToStart, return_to_start};
use slam::{Mapper2dParams, MapperStats, Pose2};
use testdata::shared_data;

/// Maps the log with `fraction` wrong closures per loop-closure match: how the run's end
/// meets its start, the stats, the last pose, and how many wrong closures became edges.
fn map(fraction: f64) -> (ReturnToStart, MapperStats, Pose2, usize) {
    let path = shared_data("radish_2d_laser_logs/fr-clinic_robotlaser.clf.bz2");
    let log = carmen::read(&path).expect("log");
    let (mapper, placed, wrong) = map_injecting(&log, fraction);
    let params = Mapper2dParams::default();
    let last = log.scans.len() - 1;
    let [first_pose, last_pose] = [0, last].map(|k| mapper.pose_of(placed[k]));
    let back = return_to_start(
        (&first_pose, &log.scans[0].to_scan2()),
        (&last_pose, &log.scans[last].to_scan2()),
        &params.idc,
        &params.gate,
    );
    let accepted = wrong.accepted(mapper.graph());
    (back, mapper.stats(), last_pose, accepted)
}

#[test]
fn fr_clinic_closes_its_last_loop_even_with_wrong_closures() {
    let (clean, stats, clean_end, _) = map(0.0);
    println!("fr-clinic: {clean:?}; {stats:?}");
    assert!(stats.global_matches >= 1, "{stats:?}");
    let correction = clean.correction_m.expect("the last scan matches the first");
    assert!(correction <= 0.5, "{clean:?}");
    let fraction = 0.11 * stats.loop_closures as f64 / stats.loop_matches as f64;
    let (dirty, dirty_stats, dirty_end, accepted) = map(fraction);
    println!("with wrong closures: {dirty:?}; {accepted} became edges; {dirty_stats:?}");
    let correction = dirty
        .correction_m
        .expect("the last scan still matches the first");
    assert!(correction <= 0.5, "{dirty:?}");
    let moved = clean_end.between(&dirty_end);
    assert!(moved.x.hypot(moved.y) <= 1.0, "the end moved {moved:?}");
}
