//! IDC scan matching on real 2D laser logs against SLAM-corrected poses (MANIFEST 2b): pairs
//! of FLASER scans 1–2 m apart, matched from the corrected relative pose perturbed by
//! (±0.2 m, ±0.2 m, ±3°), scored by their error to the corrected relative pose. The corrected
//! poses are a consistent map, not surveyed truth: they disagree with any scan matcher by a
//! few centimetres and tenths of a degree (along corridors, by up to ~13 cm), so the
//! thresholds below are set from what was measured, with margin.
//!
//! `cargo test -p slam --test carmen_idc -- --nocapture` prints the figures quoted in the
//! comments (about 15 s: slam is optimized in test builds too).

use graphio::carmen::{self, CarmenLog, FlaserBearings, LaserScan, ReadOptions};
use slam::matching::{IdcParams, Match, QualityGate, Scan2, accept, idc};
use slam::{Pose2, wrap_angle};
use testdata::shared_data;

fn read(relative: &str, flaser_bearings: FlaserBearings) -> CarmenLog {
    let options = ReadOptions {
        flaser_bearings,
        ..ReadOptions::default()
    };
    carmen::read_with(&shared_data(relative), &options).unwrap_or_else(|e| panic!("{e}"))
}

fn scan2(scan: &LaserScan) -> Scan2 {
    scan.to_scan2()
}

/// Relative corrected pose of scan j seen from scan i.
fn truth(log: &CarmenLog, i: usize, j: usize) -> Pose2 {
    log.scans[i].laser_pose.between(&log.scans[j].laser_pose)
}

/// Pairs (i, j): j is the first scan at least 1 m from scan i, kept when at most 2 m away.
fn pairs_1_to_2_m(log: &CarmenLog) -> Vec<(usize, usize)> {
    (0..log.scans.len())
        .filter_map(|i| {
            let dist = |j: usize| {
                let d = truth(log, i, j);
                d.x.hypot(d.y)
            };
            let j = (i + 1..log.scans.len()).find(|&j| dist(j) >= 1.0)?;
            (dist(j) <= 2.0).then_some((i, j))
        })
        .collect()
}

/// The k-th of the eight perturbations (±0.2 m, ±0.2 m, ±3°), in the current scan's frame.
fn perturbation(k: usize) -> Pose2 {
    let sign = |bit: usize| if (k >> bit) & 1 == 0 { 1.0 } else { -1.0 };
    Pose2::new(0.2 * sign(0), 0.2 * sign(1), 3f64.to_radians() * sign(2))
}

fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(((v.len() as f64 - 1.0) * q).round() as usize)
        .copied()
        .unwrap_or(f64::NAN)
}

/// (translation m, rotation rad) between two poses.
fn apart(a: &Pose2, b: &Pose2) -> (f64, f64) {
    let d = a.between(b);
    (d.x.hypot(d.y), d.theta.abs())
}

/// What the matches of one log measured.
#[derive(Debug)]
#[allow(dead_code)] // printed, not all asserted
struct Summary {
    pairs: usize,
    /// Error to the corrected relative pose over all pairs (a refused pair counts as ∞).
    median_m: f64,
    p90_m: f64,
    median_deg: f64,
    p90_deg: f64,
    /// Share of pairs accepted by the default gate.
    accepted: f64,
    /// Share of accepted pairs within 10 cm and 1.5° of the corrected relative pose.
    accepted_within_10_cm: f64,
    /// Share of pairs whose match from the perturbed guess equals (1 cm, 0.1°) the match
    /// from the corrected pose itself: the perturbation does not change the answer.
    same_as_from_truth: f64,
    median_quality: f64,
    median_residual_m: f64,
}

fn summarize(log: &CarmenLog, pairs: &[(usize, usize)]) -> Summary {
    let (params, gate) = (IdcParams::default(), QualityGate::default());
    let (mut errors_m, mut errors_rad, mut quality, mut residual) =
        (vec![], vec![], vec![], vec![]);
    let (mut accepted, mut accepted_good, mut same) = (0, 0, 0);
    for (k, &(i, j)) in pairs.iter().enumerate() {
        let truth = truth(log, i, j);
        let (a, b) = (scan2(&log.scans[i]), scan2(&log.scans[j]));
        let perturbed: Option<Match> = idc(&a, &b, truth.compose(&perturbation(k)), &params).ok();
        let Some(m) = perturbed else {
            errors_m.push(f64::INFINITY);
            errors_rad.push(f64::INFINITY);
            continue;
        };
        let (dt, dr) = apart(&truth, &m.pose);
        errors_m.push(dt);
        errors_rad.push(dr);
        quality.push(m.quality);
        residual.push(m.mean_residual_m);
        if accept(&m, &gate) {
            accepted += 1;
            accepted_good += usize::from(dt < 0.1 && dr < 1.5f64.to_radians());
        }
        if let Ok(from_truth) = idc(&a, &b, truth, &params) {
            let (dt, dr) = apart(&from_truth.pose, &m.pose);
            same += usize::from(dt < 0.01 && dr < 0.1f64.to_radians());
        }
    }
    let n = pairs.len().max(1) as f64;
    Summary {
        pairs: pairs.len(),
        median_m: quantile(errors_m.clone(), 0.5),
        p90_m: quantile(errors_m, 0.9),
        median_deg: quantile(errors_rad.clone(), 0.5).to_degrees(),
        p90_deg: quantile(errors_rad, 0.9).to_degrees(),
        accepted: accepted as f64 / n,
        accepted_within_10_cm: accepted_good as f64 / accepted.max(1) as f64,
        same_as_from_truth: same as f64 / n,
        median_quality: quantile(quality, 0.5),
        median_residual_m: quantile(residual, 0.5),
    }
}

#[test]
fn idc_matches_corrected_aces_indoor() {
    let log = read(
        "radish_2d_corrected_logs/aces-corrected.log.gz",
        FlaserBearings::Carmen,
    );
    let pairs = pairs_1_to_2_m(&log);
    let s = summarize(&log, &pairs);
    eprintln!("aces-corrected: {s:#?}");
    // Measured (392 pairs): median 4.1 cm / 0.32°, p90 16 cm / 1.6°; accepted 88 %,
    // of which 89 % within 10 cm and 1.5° (the rest mostly along corridors, where neither
    // the matcher nor the corrected poses are sure); 81 % give the same answer as from the
    // corrected pose itself.
    assert!(s.pairs > 300, "{} pairs", s.pairs);
    assert!(s.median_m < 0.05 && s.median_deg < 0.5, "{s:?}");
    assert!(s.accepted > 0.8 && s.accepted_within_10_cm > 0.8, "{s:?}");
    assert!(s.same_as_from_truth > 0.75, "{s:?}");
}

#[test]
fn idc_matches_corrected_freiburg_campus_outdoor() {
    let log = read(
        "radish_2d_corrected_logs/freiburg-campus-corrected.log.gz",
        FlaserBearings::Carmen,
    );
    let pairs = pairs_1_to_2_m(&log);
    let s = summarize(&log, &pairs);
    eprintln!("freiburg-campus-corrected: {s:#?}");
    // Measured (1835 pairs): median 2.8 cm / 0.11°, p90 42 cm / 1.3°; accepted
    // 81 %, of which 94 % within 10 cm and 1.5°; 83 % give the same answer as from the
    // corrected pose itself.
    assert!(s.pairs > 1500, "{} pairs", s.pairs);
    assert!(s.median_m < 0.05 && s.median_deg < 0.5, "{s:?}");
    assert!(s.accepted > 0.7 && s.accepted_within_10_cm > 0.9, "{s:?}");
    assert!(s.same_as_from_truth > 0.75, "{s:?}");
}

#[test]
fn scans_of_different_places_on_the_campus_are_rejected() {
    // Scan i against scan i + 1000: hundreds of metres apart on a 1.75 km loop, from the
    // guess a robot would make (1 m ahead).
    let log = read(
        "radish_2d_corrected_logs/freiburg-campus-corrected.log.gz",
        FlaserBearings::Carmen,
    );
    let (params, gate) = (IdcParams::default(), QualityGate::default());
    let (mut tried, mut accepted) = (0, 0);
    for i in (0..log.scans.len() - 1000).step_by(4) {
        let j = i + 1000;
        let d = truth(&log, i, j);
        if d.x.hypot(d.y) < 30.0 {
            continue; // the loop comes back: not a wrong pairing
        }
        tried += 1;
        if let Ok(m) = idc(
            &scan2(&log.scans[i]),
            &scan2(&log.scans[j]),
            Pose2::new(1.0, 0.0, 0.0),
            &params,
        ) {
            accepted += usize::from(accept(&m, &gate));
        }
    }
    // Measured: 0 of 192 accepted.
    eprintln!("wrong pairings: {accepted} of {tried} accepted");
    assert!(tried > 150);
    assert!(
        (accepted as f64) < 0.02 * tried as f64,
        "{accepted} of {tried} wrong pairings accepted"
    );
}

/// Pairs (i, j): j is the first scan after i turned by at least 20° from it (corrected
/// poses), within 30 scans and 2 m.
fn turning_pairs(log: &CarmenLog) -> Vec<(usize, usize)> {
    let s = &log.scans;
    (0..s.len())
        .filter_map(|i| {
            let j = (i + 1..s.len().min(i + 30))
                .find(|&j| truth(log, i, j).theta.abs() >= 20f64.to_radians())?;
            let d = truth(log, i, j);
            (d.x.hypot(d.y) <= 2.0).then_some((i, j))
        })
        .collect()
}

/// Least-squares slope of (matched − corrected rotation) against the corrected rotation,
/// over the accepted matches of turning pairs. A bearing step off by a factor k stretches
/// every scan about beam 0, and a turn θ then matches as about θ / k: the slope is the
/// step's relative error plus whatever scale bias the corrected poses have.
fn rotation_slope(log: &CarmenLog, pairs: &[(usize, usize)]) -> (f64, usize) {
    let (params, gate) = (IdcParams::default(), QualityGate::default());
    let (mut sxx, mut sxy, mut n) = (0.0, 0.0, 0);
    for (k, &(i, j)) in pairs.iter().enumerate() {
        let truth = truth(log, i, j);
        let initial = truth.compose(&perturbation(k));
        if let Ok(m) = idc(
            &scan2(&log.scans[i]),
            &scan2(&log.scans[j]),
            initial,
            &params,
        ) && accept(&m, &gate)
        {
            sxx += truth.theta * truth.theta;
            sxy += truth.theta * wrap_angle(m.pose.theta - truth.theta);
            n += 1;
        }
    }
    (sxy / sxx, n)
}

/// FLASER carries no angles: is the step π/n or π/(n − 1)? With the wrong one, turns match
/// with a scale error of 1/n (0.56 % for 180 beams, 0.28 % for 360). Measured slopes
/// (CARMEN's step first): ACES +0.0020 vs +0.0076, Intel −0.0012 vs +0.0041,
/// campus +0.0009 vs +0.0031, CSAIL −0.0026 vs −0.0051, Freiburg 079 −0.0029 vs −0.0005.
/// The differences are the predicted 1/n; CARMEN's own rule (1° for 180 beams, 0.5° for
/// 360 and 361) wins in four logs of five. Freiburg 079 prefers π/359: its corrected turns
/// carry a scale bias of about −0.3 % of their own (CSAIL's too, under either step), so it
/// is reported, not asserted.
#[test]
fn flaser_bearing_convention() {
    let logs = [
        ("aces-corrected.log.gz", 180, true),
        ("intel-corrected.log.gz", 180, true),
        ("freiburg-campus-corrected.log.gz", 360, true),
        ("freiburg-079-corrected.log.gz", 360, false),
        ("csail-corrected.log.gz", 361, true),
    ];
    for (file, beams, asserted) in logs {
        let mut slopes = Vec::new();
        for convention in [FlaserBearings::PiOverN, FlaserBearings::PiOverNMinusOne] {
            let log = read(&format!("radish_2d_corrected_logs/{file}"), convention);
            let pairs = turning_pairs(&log);
            let (slope, n) = rotation_slope(&log, &pairs);
            eprintln!(
                "{file} ({beams} beams), step {convention:?}: rotation error slope {slope:+.4} \
                 over {n} accepted of {} turning pairs",
                pairs.len()
            );
            slopes.push(slope);
        }
        // CARMEN's step is π/n for 180 and 360 beams, π/(n − 1) for 361.
        let (carmen, other) = if beams == 361 {
            (slopes[1], slopes[0])
        } else {
            (slopes[0], slopes[1])
        };
        if asserted {
            assert!(
                carmen.abs() < other.abs(),
                "{file}: slope {carmen} with CARMEN's step, {other} without"
            );
        }
    }
}
