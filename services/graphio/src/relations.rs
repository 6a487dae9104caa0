//! Relations files of Kümmerle et al. 2009 ("On measuring the accuracy of SLAM algorithms"):
//! one manually verified relative pose per line,
//! `timestamp1 timestamp2 x y z roll pitch yaw` — the pose of the robot at `timestamp2` in the
//! frame of the robot at `timestamp1` (m, rad). The timestamps are the FLASER
//! `ipc_timestamp`s of the matching CARMEN log. Score a trajectory with
//! [`slam::matching::metric::relation_metric`].
//!
//! The files are 2D: z, roll and pitch must be 0; a relation that is not planar is an error,
//! not silently flattened. Blank lines and `#` comments are skipped.

use crate::FileError;
use crate::carmen::LaserScan;
use crate::carmen::{for_each_line, open_decompressed};
use slam::Pose2;
use slam::matching::metric::{MetricError, RelationMetric, relation_metric};
use std::collections::HashMap;
use std::io::BufRead;
use std::path::Path;

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
}

/// Reads a relations file (plain, `.gz` or `.bz2`). Errors name the file and line.
pub fn read(path: &Path) -> Result<Vec<Relation>, FileError> {
    parse(open_decompressed(path)?, path)
}

/// Scores the poses of a log's scans against relations: each relation's timestamps are
/// looked up among the scans' `stamp_s` exactly (they are the FLASER `ipc_timestamp`s), and
/// `pose_of_scan(k)` gives the pose of scan `k`. A relation without its scans is an error.
pub fn score(
    relations: &[Relation],
    scans: &[LaserScan],
    pose_of_scan: impl Fn(usize) -> Pose2,
) -> Result<RelationMetric, MetricError> {
    let by_stamp: HashMap<u64, usize> = scans
        .iter()
        .enumerate()
        .map(|(k, s)| (s.stamp_s.to_bits(), k))
        .collect();
    relation_metric(
        relations.iter().map(|r| (r.t1_s, r.t2_s, r.delta)),
        |t: &f64| by_stamp.get(&t.to_bits()).map(|&k| pose_of_scan(k)),
    )
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
                delta: Pose2::new(0.42233, -0.00075, 0.01726)
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
}
