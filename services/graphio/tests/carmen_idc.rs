//! IDC scan matching on real 2D laser logs against SLAM-corrected poses (MANIFEST 2b): pairs
//! of FLASER scans 1–2 m apart, matched from the corrected relative pose perturbed by
//! (±0.2 m, ±0.2 m, ±3°), scored by their error to the corrected relative pose. The corrected
//! poses are a consistent map, not surveyed truth: centimetres of disagreement are expected.
//!
//! Slow in a debug build; `cargo test -p graphio --release --test carmen_idc -- --nocapture`
//! prints the figures.

use graphio::carmen::{self, CarmenLog, FlaserBearings, LaserScan, ReadOptions};
use scanio::shared_data;
use slam::Pose2;
use slam::matching::{IdcParams, QualityGate, Scan2, accept, idc};

fn read(relative: &str, flaser_bearings: FlaserBearings) -> CarmenLog {
    let options = ReadOptions {
        flaser_bearings,
        ..ReadOptions::default()
    };
    carmen::read_with(&shared_data(relative), &options).unwrap_or_else(|e| panic!("{e}"))
}

fn scan2(scan: &LaserScan) -> Scan2 {
    Scan2::from_polar(&scan.bearings_rad(), &scan.ranges_m, scan.max_range_m)
        .expect("one range per bearing")
}

/// Pairs (i, j): j is the first scan at least `min_m` from scan i (by corrected pose), kept
/// when it is at most `max_m` away; every `every`-th i.
fn pairs(log: &CarmenLog, min_m: f64, max_m: f64, every: usize) -> Vec<(usize, usize)> {
    let s = &log.scans;
    (0..s.len())
        .step_by(every)
        .filter_map(|i| {
            let dist = |j: usize| {
                (s[j].laser_pose.x - s[i].laser_pose.x).hypot(s[j].laser_pose.y - s[i].laser_pose.y)
            };
            let j = (i + 1..s.len()).find(|&j| dist(j) >= min_m)?;
            (dist(j) <= max_m).then_some((i, j))
        })
        .collect()
}

/// The k-th of the eight perturbations (±0.2 m, ±0.2 m, ±3°), in the current scan's frame.
fn perturbation(k: usize) -> Pose2 {
    let sign = |bit: usize| if k >> bit & 1 == 0 { 1.0 } else { -1.0 };
    Pose2::new(0.2 * sign(0), 0.2 * sign(1), 3f64.to_radians() * sign(2))
}

#[derive(Clone, Copy, Debug)]
struct Outcome {
    translation_m: f64,
    rotation_rad: f64,
    accepted: bool,
    residual_m: f64,
    quality: f64,
}

/// Matches every pair; a pair IDC refuses counts as rejected with an infinite error.
fn run(
    log: &CarmenLog,
    pairs: &[(usize, usize)],
    params: &IdcParams,
    gate: &QualityGate,
) -> Vec<Outcome> {
    pairs
        .iter()
        .enumerate()
        .map(|(k, &(i, j))| {
            let (a, b) = (&log.scans[i], &log.scans[j]);
            let truth = a.laser_pose.between(&b.laser_pose);
            let initial = truth.compose(&perturbation(k));
            match idc(&scan2(a), &scan2(b), initial, params) {
                Ok(m) => {
                    let e = truth.between(&m.pose);
                    Outcome {
                        translation_m: e.x.hypot(e.y),
                        rotation_rad: e.theta.abs(),
                        accepted: accept(&m, gate),
                        residual_m: m.mean_residual_m,
                        quality: m.quality,
                    }
                }
                Err(_) => Outcome {
                    translation_m: f64::INFINITY,
                    rotation_rad: f64::INFINITY,
                    accepted: false,
                    residual_m: f64::INFINITY,
                    quality: 0.0,
                },
            }
        })
        .collect()
}

fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(((v.len() as f64 - 1.0) * q).round() as usize)
        .copied()
        .unwrap_or(f64::NAN)
}

#[derive(Debug)]
struct Summary {
    pairs: usize,
    median_m: f64,
    p90_m: f64,
    median_deg: f64,
    p90_deg: f64,
    median_residual_m: f64,
    accepted: f64,
    /// Among accepted pairs: share within 10 cm and 1°.
    accepted_good: f64,
    median_quality: f64,
}

fn summarize(name: &str, outcomes: &[Outcome]) -> Summary {
    let all = |f: fn(&Outcome) -> f64| outcomes.iter().map(f).collect::<Vec<_>>();
    let accepted: Vec<&Outcome> = outcomes.iter().filter(|o| o.accepted).collect();
    let good = accepted
        .iter()
        .filter(|o| o.translation_m < 0.1 && o.rotation_rad < 1f64.to_radians())
        .count();
    let s = Summary {
        pairs: outcomes.len(),
        median_m: quantile(all(|o| o.translation_m), 0.5),
        p90_m: quantile(all(|o| o.translation_m), 0.9),
        median_deg: quantile(all(|o| o.rotation_rad), 0.5).to_degrees(),
        p90_deg: quantile(all(|o| o.rotation_rad), 0.9).to_degrees(),
        median_residual_m: quantile(all(|o| o.residual_m), 0.5),
        accepted: accepted.len() as f64 / outcomes.len().max(1) as f64,
        accepted_good: good as f64 / accepted.len().max(1) as f64,
        median_quality: quantile(all(|o| o.quality), 0.5),
    };
    eprintln!("{name}: {s:?}");
    s
}

#[test]
fn idc_on_corrected_aces_and_campus() {
    let params = IdcParams::default();
    let gate = QualityGate::default();
    for (file, every) in [
        ("aces-corrected.log.gz", 1),
        ("freiburg-campus-corrected.log.gz", 1),
    ] {
        let log = read(
            &format!("radish_2d_corrected_logs/{file}"),
            FlaserBearings::Carmen,
        );
        let pairs = pairs(&log, 1.0, 2.0, every);
        let s = summarize(file, &run(&log, &pairs, &params, &gate));
        assert!(s.pairs > 100, "{file}: {} pairs", s.pairs);
    }
}

/// Pairs (i, j): j is the first scan after i turned by at least `min_rad` from it (corrected
/// poses), kept when at most 2 m away; every `every`-th i.
fn turning_pairs(log: &CarmenLog, min_rad: f64, every: usize) -> Vec<(usize, usize)> {
    let s = &log.scans;
    (0..s.len())
        .step_by(every)
        .filter_map(|i| {
            let j = (i + 1..s.len().min(i + 30)).find(|&j| {
                s[i].laser_pose.between(&s[j].laser_pose).theta.abs() >= min_rad
            })?;
            let d = s[i].laser_pose.between(&s[j].laser_pose);
            (d.x.hypot(d.y) <= 2.0).then_some((i, j))
        })
        .collect()
}

/// Slope of (matched − corrected rotation) against the corrected rotation over accepted
/// matches of turning pairs, and their median mean residual (m). A wrong bearing step
/// stretches every scan about beam 0, so a turn of θ matches as about θ·(true step / used
/// step): the slope measures the step's relative error.
fn rotation_slope(log: &CarmenLog, pairs: &[(usize, usize)]) -> (f64, f64, usize) {
    let (params, gate) = (IdcParams::default(), QualityGate::default());
    let (mut sxx, mut sxy, mut residuals) = (0.0, 0.0, Vec::new());
    for (k, &(i, j)) in pairs.iter().enumerate() {
        let (a, b) = (&log.scans[i], &log.scans[j]);
        let truth = a.laser_pose.between(&b.laser_pose);
        let initial = truth.compose(&perturbation(k));
        if let Ok(m) = idc(&scan2(a), &scan2(b), initial, &params)
            && accept(&m, &gate)
        {
            let error = slam::wrap_angle(m.pose.theta - truth.theta);
            sxx += truth.theta * truth.theta;
            sxy += truth.theta * error;
            residuals.push(m.mean_residual_m);
        }
    }
    let n = residuals.len();
    (sxy / sxx, quantile(residuals, 0.5), n)
}

#[test]
fn flaser_bearing_convention() {
    // (log, beams per scan): the 180-beam logs tell π/180 from π/179, the 360-beam logs
    // π/360 from π/359, the 361-beam log π/360 from π/361.
    let logs = [
        ("aces-corrected.log.gz", 180),
        ("intel-corrected.log.gz", 180),
        ("freiburg-campus-corrected.log.gz", 360),
        ("freiburg-079-corrected.log.gz", 360),
        ("csail-corrected.log.gz", 361),
    ];
    for (file, beams) in logs {
        let mut slopes = Vec::new();
        for convention in [FlaserBearings::PiOverN, FlaserBearings::PiOverNMinusOne] {
            let log = read(&format!("radish_2d_corrected_logs/{file}"), convention);
            let pairs = turning_pairs(&log, 20f64.to_radians(), 1);
            let (slope, residual, n) = rotation_slope(&log, &pairs);
            eprintln!(
                "{file} ({beams} beams) step {convention:?}: rotation error slope {:+.4} over {n} \
                 accepted turning pairs of {}, median residual {:.4} m",
                slope,
                pairs.len(),
                residual
            );
            slopes.push(slope);
        }
        // CARMEN's step is π/n for 180 and 360 beams, π/(n − 1) for 361: it must be the one
        // whose turns match the corrected turns without a scale error.
        let (carmen, other) = if beams == 361 { (slopes[1], slopes[0]) } else { (slopes[0], slopes[1]) };
        eprintln!("{carmen} {other}");
    }
}

#[test]
fn debug_pairs() {
    let env = |k: &str, d: f64| std::env::var(k).ok().and_then(|v| v.parse().ok()).unwrap_or(d);
    let params = IdcParams {
        shrink: env("DBG_SHRINK", 0.7),
        initial_rotation_window_rad: env("DBG_WINDOW", 0.25),
        final_max_distance_m: env("DBG_FINAL", 0.2),
        ..IdcParams::default()
    };
    let file = std::env::var("DBG_FILE").unwrap_or("freiburg-079-corrected.log.gz".into());
    let zero = std::env::var_os("DBG_ZERO").is_some();
    let log = read(
        &format!("radish_2d_corrected_logs/{file}"),
        FlaserBearings::Carmen,
    );
    let pairs = pairs(&log, 1.0, 2.0, 7);
    let mut errs = vec![];
    let only: Option<usize> = std::env::var("DBG_PAIR").ok().and_then(|v| v.parse().ok());
    let t0 = std::time::Instant::now();
    for (k, &(i, j)) in pairs.iter().enumerate().take(150) {
        if only.is_some_and(|o| o != k) {
            continue;
        }
        let (a, b) = (&log.scans[i], &log.scans[j]);
        let truth = a.laser_pose.between(&b.laser_pose);
        let initial = if zero {
            truth
        } else {
            truth.compose(&perturbation(k))
        };
        let r = idc(&scan2(a), &scan2(b), initial, &params);
        match r {
            Ok(m) => {
                let e = truth.between(&m.pose);
                errs.push(e.x.hypot(e.y));
                eprintln!(
                    "{k:3} {i:5} {j:5} dt {:.3} dr {:6.2} conv {} it {:2} q {:.2} in {:.2} conf {:.2} res {:.3} cond {:.4} acc {} truth {:.2} {:.2} {:.1} e {:.3} {:.3}",
                    e.x.hypot(e.y),
                    e.theta.to_degrees(),
                    m.converged,
                    m.iterations,
                    m.quality,
                    m.inlier_share,
                    m.conflict_share,
                    m.mean_residual_m,
                    m.conditioning,
                    accept(&m, &QualityGate::default()),
                    truth.x,
                    truth.y,
                    truth.theta.to_degrees(),
                    e.x,
                    e.y
                );
            }
            Err(e) => eprintln!("{k:3} err {e}"),
        }
    }
    eprintln!("median {:.4} time {:?}", quantile(errs, 0.5), t0.elapsed());
}
