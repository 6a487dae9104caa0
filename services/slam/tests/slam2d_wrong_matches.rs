//! Wrong sequential matches on real logs: each log is mapped clean, then again with 2 % of
//! its nodes' matches with their robot's last node moved off by 0.3–1 m and 2–10°
//! (`slam::WrongMatches`), and the relation error (Kümmerle et al. 2009) must stay within 10 %
//! of the clean run's: the mapper must find them (each match is gated where it puts the new
//! scan, against the last node's scan, and searched again on the local map when it fails;
//! `mapping2d/local.rs`).

mod common;

use common::map_with_faults;
use graphio::{carmen, relations};
use testdata::shared_data;

/// Wrong matches per node.
const FRACTION: f64 = 0.02;

/// Maps `name` with `fraction` wrong matches per node: the relation error's mean (m), how
/// many wrong matches went in and how many became edges.
fn map(name: &str, fraction: f64) -> (f64, usize, usize) {
    let path = |ext: &str| shared_data(&format!("radish_2d_laser_logs/{name}.{ext}"));
    let log = carmen::read(&path("clf.bz2")).expect("log");
    let rel = relations::read(&path("relations")).expect("relations");
    let (mapper, placed, _, wrong) = map_with_faults(&log, 0.0, fraction);
    let m = relations::score(&rel, &log.scans, |k| mapper.pose_of(placed[k]))
        .expect("every relation has its scans");
    (
        m.translation_mean_m,
        wrong.injected(&mapper),
        wrong.accepted(&mapper),
    )
}

fn holds_against_wrong_matches(name: &str) {
    let (clean, ..) = map(name, 0.0);
    let (dirty, injected, accepted) = map(name, FRACTION);
    println!(
        "{name}: clean {clean:.4} m; with {injected} wrong matches {dirty:.4} m \
         ({accepted} of them edges)"
    );
    assert!(injected >= 5, "{injected} wrong matches injected");
    assert!(
        dirty <= 1.1 * clean,
        "clean {clean}, with wrong matches {dirty}"
    );
}

#[test]
fn intel_holds_against_wrong_matches() {
    holds_against_wrong_matches("intel");
}

#[test]
fn aces_holds_against_wrong_matches() {
    holds_against_wrong_matches("aces");
}

#[test]
fn fr079_holds_against_wrong_matches() {
    holds_against_wrong_matches("fr079");
}
