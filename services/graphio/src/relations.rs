//! Relations files of Kümmerle et al. 2009 ("On measuring the accuracy of SLAM algorithms"):
//! one manually verified relative pose per line,
//! `timestamp1 timestamp2 x y z roll pitch yaw` — the pose of the robot at `timestamp2` in the
//! frame of the robot at `timestamp1` (m, rad). The timestamps are the FLASER
//! `ipc_timestamp`s of the matching CARMEN log, as published: some files round them to five
//! decimals where the log has six, so [`score`] takes the scan nearest to each, within
//! [`STAMP_TOLERANCE_S`].
//!
//! The files are 2D: z, roll and pitch must be 0; a relation that is not planar is an error,
//! not silently flattened. Blank lines and `#` comments are skipped.

use crate::FileError;
use crate::carmen::LaserScan;
use crate::carmen::{for_each_line, open_decompressed};
use slam::Pose2;
use slam::matching::metric::{MetricError, RelationMetric, relation_metric};
use std::io::BufRead;
use std::path::Path;

/// How far a relation's timestamp may be from its scan's: half the last digit of a file
/// rounded to four decimals, ten times a five-decimal rounding's error, and far below the
/// logs' scan interval (13 ms or more).
pub const STAMP_TOLERANCE_S: f64 = 1e-4;

/// The fields of a line, in order.
const NAMES: [&str; 8] = [
    "timestamp1",
    "timestamp2",
    "x",
    "y",
    "z",
    "roll",
    "pitch",
    "yaw",
];

/// One relation: the robot at `t2_s` seen from the robot at `t1_s`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Relation {
    /// First timestamp (s).
    pub t1_s: f64,
    /// Second timestamp (s).
    pub t2_s: f64,
    /// `x₁⁻¹ ⊕ x₂` as measured (m, rad).
    pub delta: Pose2,
    /// The file's 1-based line, for errors.
    pub line: usize,
}

/// Reads a relations file (plain, `.gz` or `.bz2`). Errors name the file and line.
pub fn read(path: &Path) -> Result<Vec<Relation>, FileError> {
    parse(open_decompressed(path)?, path)
}

/// A relation that cannot be scored.
#[derive(Debug, thiserror::Error)]
pub enum ScoreError {
    /// A timestamp has no scan within [`STAMP_TOLERANCE_S`].
    #[error(
        "line {line}: no scan within {STAMP_TOLERANCE_S} s of timestamp {stamp_s} (nearest: {nearest})"
    )]
    NoScan {
        /// The relation's line.
        line: usize,
        /// Its timestamp (s).
        stamp_s: f64,
        /// The nearest scan's timestamp, or "none" in a log without scans.
        nearest: String,
    },
    /// The metric failed (a pose not finite).
    #[error(transparent)]
    Metric(#[from] MetricError),
}

/// Scores the poses of a log's scans against relations: each relation's timestamps are
/// matched to the scan with the nearest `stamp_s` (within [`STAMP_TOLERANCE_S`]), and
/// `pose_of_scan(k)` gives the pose of scan `k`. A relation without its scans is an error.
pub fn score(
    relations: &[Relation],
    scans: &[LaserScan],
    pose_of_scan: impl Fn(usize) -> Pose2,
) -> Result<RelationMetric, ScoreError> {
    let mut by_stamp: Vec<(f64, usize)> = scans
        .iter()
        .enumerate()
        .map(|(k, s)| (s.stamp_s, k))
        .collect();
    by_stamp.sort_by(|a, b| a.0.total_cmp(&b.0));
    let scan_at = |stamp_s: f64, line: usize| {
        let after = by_stamp.partition_point(|&(t, _)| t < stamp_s);
        let nearest = [after.checked_sub(1), Some(after)]
            .into_iter()
            .flatten()
            .filter_map(|i| by_stamp.get(i))
            .min_by(|a, b| (a.0 - stamp_s).abs().total_cmp(&(b.0 - stamp_s).abs()));
        match nearest {
            Some(&(t, k)) if (t - stamp_s).abs() <= STAMP_TOLERANCE_S => Ok(k),
            _ => Err(ScoreError::NoScan {
                line,
                stamp_s,
                nearest: nearest.map_or("none".into(), |(t, _)| t.to_string()),
            }),
        }
    };
    let mut pairs = Vec::with_capacity(relations.len());
    for r in relations {
        pairs.push((scan_at(r.t1_s, r.line)?, scan_at(r.t2_s, r.line)?, r.delta));
    }
    Ok(relation_metric(pairs, |&k: &usize| Some(pose_of_scan(k)))?)
}

/// Parses relations from `reader`; `path` names it in errors.
pub fn parse(reader: impl BufRead, path: &Path) -> Result<Vec<Relation>, FileError> {
    let mut relations = Vec::new();
    for_each_line(reader, path, |line, text| {
        let fields: Vec<&str> = text.split_ascii_whitespace().collect();
        if fields.first().is_none_or(|f| f.starts_with('#')) {
            return Ok(());
        }
        let error = |message: String| FileError::Line {
            path: path.to_owned(),
            line,
            message,
        };
        if fields.len() != 8 {
            return Err(error(format!(
                "{} fields, 8 expected (t1 t2 x y z roll pitch yaw)",
                fields.len()
            )));
        }
        let mut v = [0.0; 8];
        for (i, (text, name)) in fields.iter().zip(NAMES).enumerate() {
            v[i] = match text.parse::<f64>() {
                Ok(x) if x.is_finite() => x,
                _ => return Err(error(format!("{name} is not a finite number: {text:?}"))),
            };
        }
        if v[4] != 0.0 || v[5] != 0.0 || v[6] != 0.0 {
            return Err(error(format!(
                "not planar: z {} roll {} pitch {}",
                v[4], v[5], v[6]
            )));
        }
        relations.push(Relation {
            t1_s: v[0],
            t2_s: v[1],
            delta: Pose2::new(v[2], v[3], v[7]),
            line,
        });
        Ok(())
    })?;
    Ok(relations)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_str(text: &str) -> Result<Vec<Relation>, FileError> {
        parse(text.as_bytes(), Path::new("t.relations"))
    }

    #[test]
    fn reads_relations() {
        let text = "# t1 t2 x y z roll pitch yaw\n\
                    90.239599 90.719599 0.422330 -0.000750 0.000000 0.000000 0.000000 0.017260\n\n";
        let r = parse_str(text).expect("valid");
        assert_eq!(
            r,
            vec![Relation {
                t1_s: 90.239599,
                t2_s: 90.719599,
                delta: Pose2::new(0.42233, -0.00075, 0.01726),
                line: 2,
            }]
        );
    }

    #[test]
    fn bad_lines_name_the_line() {
        let good = "1 2 0 0 0 0 0 0\n";
        for (bad, says) in [
            ("1 2 0 0 0 0 0\n", "7 fields"),
            ("1 2 0 nan 0 0 0 0\n", "y is not a finite number"),
            ("1 2 0 0.x 0 0 0 0\n", "y is not a finite number"),
            ("1 2 0 0 0.5 0 0 0\n", "not planar"),
        ] {
            let err = parse_str(&format!("{good}{bad}")).unwrap_err().to_string();
            assert!(
                err.starts_with("t.relations:2: ") && err.contains(says),
                "{err}"
            );
        }
    }

    fn scan_at(stamp_s: f64, x: f64) -> LaserScan {
        LaserScan {
            stamp_s,
            logger_stamp_s: stamp_s,
            first_bearing_rad: 0.0,
            bearing_step_rad: 0.0,
            ranges_m: Vec::new(),
            max_range_m: 0.0,
            laser_pose: Pose2::new(x, 0.0, 0.0),
            odom_pose: Pose2::new(x, 0.0, 0.0),
        }
    }

    #[test]
    fn rounded_timestamps_find_their_scans() {
        let scans = [scan_at(10.123456, 0.0), scan_at(10.456789, 1.0)];
        // Rounded to five decimals, as some published files are; the delta is exact.
        let rel = parse_str("10.12346 10.45679 1 0 0 0 0 0\n").expect("valid");
        let m = score(&rel, &scans, |k| scans[k].laser_pose).expect("scored");
        assert!(m.translation_max_m < 1e-12, "{m:?}");
    }

    #[test]
    fn a_timestamp_without_its_scan_names_the_line() {
        let scans = [scan_at(10.123456, 0.0), scan_at(10.456789, 1.0)];
        let rel = parse_str("# header\n10.123456 10.4570 1 0 0 0 0 0\n").expect("valid");
        let err = score(&rel, &scans, |k| scans[k].laser_pose)
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("line 2: no scan within 0.0001 s of timestamp 10.457")
                && err.contains("nearest: 10.456789"),
            "{err}"
        );
        let err = score(&rel, &[], |_| Pose2::IDENTITY).unwrap_err();
        assert!(err.to_string().contains("nearest: none"), "{err}");
    }
}
