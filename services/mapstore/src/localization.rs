//! Localization in the store: each robot's mode (map, or localize on a version) as an
//! operator set it, and the spans of nodes localized instead of mapped (one row per
//! unbroken run, rewritten as it grows: the table grows with mode changes, not with time).

use super::{Store, StoreError};
use fleetmap::LocalizedSpan;
use redb::{ReadTransaction, ReadableTable, TableDefinition, WriteTransaction};

/// (fleet, robot, chain_id, first node_seq) → the run's last node_seq, and for a run passed
/// over covered ground (not localized on a version) the chain's passes: how many, their
/// path (m), the last one's odometry (x, y, θ); NaN path for a localized run.
type SpanRow = (u64, u64, f64, f64, f64, f64);
pub(super) const LOCALIZED: TableDefinition<(&str, &str, u64, u64), SpanRow> =
    TableDefinition::new("localized_spans");
/// A passed run's last pass on the map, keyed as its span: (x, y, θ) and the path since a
/// pass was last located (m). A table of its own, so that spans stored before it was kept
/// read as they were (their chains' next nodes then go on from their last added node).
type PassPoseRow = (f64, f64, f64, f64);
pub(super) const PASS_POSES: TableDefinition<(&str, &str, u64, u64), PassPoseRow> =
    TableDefinition::new("pass_poses");
/// (fleet, robot) → the version the robot localizes on, 0 to map; robot "" is the fleet's
/// setting for robots without one of their own.
pub(super) const MODES: TableDefinition<(&str, &str), u64> = TableDefinition::new("robot_modes");

/// A fleet's modes: the fleet's and each robot's own, by version (0: map).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct StoredModes {
    /// The fleet's setting, if one was made.
    pub fleet: Option<u64>,
    /// (robot, version) of robots with a setting of their own.
    pub robots: Vec<(String, u64)>,
}

/// Why a mode was not set, or a version not deleted.
#[derive(Debug, thiserror::Error)]
pub enum ModeError {
    /// The version does not exist.
    #[error("fleet {fleet} has no version {version}")]
    NoVersion {
        /// The fleet.
        fleet: String,
        /// The version.
        version: u64,
    },
    /// Robots localize on the version: it cannot be deleted.
    #[error(
        "version {version} of fleet {fleet} is in use: {robots} robot setting(s) localize on it"
    )]
    InUse {
        /// The fleet.
        fleet: String,
        /// The version.
        version: u64,
        /// Settings that use it (the fleet's counts as one).
        robots: usize,
    },
    /// The store failed.
    #[error(transparent)]
    Store(#[from] StoreError),
}

/// Makes the tables when missing.
pub(super) fn open_tables(txn: &WriteTransaction) -> Result<(), StoreError> {
    txn.open_table(LOCALIZED)?;
    txn.open_table(PASS_POSES)?;
    txn.open_table(MODES)?;
    Ok(())
}

/// Writes a batch's spans (each the run as it stands now).
pub(super) fn write_spans(
    txn: &WriteTransaction,
    fleet: &str,
    spans: &[LocalizedSpan],
) -> Result<(), StoreError> {
    let mut table = txn.open_table(LOCALIZED)?;
    let mut poses = txn.open_table(PASS_POSES)?;
    for s in spans {
        let key = (fleet, s.robot.as_str(), s.chain_id, s.first_seq);
        let row = match s.passed {
            Some(p) => {
                let o = p.odometry.unwrap_or(slam::Pose2::IDENTITY);
                (s.last_seq, p.nodes as u64, p.path_m, o.x, o.y, o.theta)
            }
            None => (s.last_seq, 0, f64::NAN, 0.0, 0.0, 0.0),
        };
        table.insert(key, row)?;
        // A run extended without a pose (a format-1 record of an earlier release's host)
        // keeps no earlier pass's pose: the chain then goes on from its last added node.
        match s
            .passed
            .and_then(|p| p.pose.map(|pose| (pose, p.unlocated_m)))
        {
            Some((pose, unlocated_m)) => {
                poses.insert(key, (pose.x, pose.y, pose.theta, unlocated_m))?;
            }
            None => {
                poses.remove(key)?;
            }
        }
    }
    Ok(())
}

/// Sets `robots` of `fleet` (every robot with `None`: the fleet's setting, each robot's own
/// removed) to `version` (0: map).
pub(super) fn write_modes(
    txn: &WriteTransaction,
    fleet: &str,
    robots: Option<&[String]>,
    version: u64,
) -> Result<(), StoreError> {
    let mut table = txn.open_table(MODES)?;
    match robots {
        None => {
            table.retain_in((fleet, "")..=(fleet, "\u{10ffff}"), |_, _| false)?;
            table.insert((fleet, ""), version)?;
        }
        Some(robots) => {
            for robot in robots {
                table.insert((fleet, robot.as_str()), version)?;
            }
        }
    }
    Ok(())
}

/// A fleet's spans.
pub(super) fn read_spans(
    txn: &ReadTransaction,
    fleet: &str,
) -> Result<Vec<LocalizedSpan>, StoreError> {
    let table = txn.open_table(LOCALIZED)?;
    let poses = txn.open_table(PASS_POSES)?;
    let range = (fleet, "", 0u64, 0u64)..;
    let mut spans = Vec::new();
    for entry in table.range(range)? {
        let (k, v) = entry?;
        let (f, robot, chain_id, first_seq) = k.value();
        if f != fleet {
            break;
        }
        let (last_seq, nodes, path_m, x, y, theta) = v.value();
        let at = poses.get(k.value())?.map(|row| row.value());
        let passed = (!path_m.is_nan()).then(|| slam::Passed {
            nodes: nodes as usize,
            path_m,
            odometry: Some(slam::Pose2::new(x, y, theta)),
            pose: at.map(|(x, y, theta, _)| slam::Pose2::new(x, y, theta)),
            unlocated_m: at.map_or(0.0, |a| a.3),
        });
        spans.push(LocalizedSpan {
            robot: robot.to_owned(),
            chain_id,
            first_seq,
            last_seq,
            passed,
        });
    }
    Ok(spans)
}

/// The fleets with spans.
pub(super) fn span_fleets(txn: &ReadTransaction) -> Result<Vec<String>, StoreError> {
    let table = txn.open_table(LOCALIZED)?;
    let mut fleets: Vec<String> = Vec::new();
    for entry in table.iter()? {
        let fleet = entry?.0.value().0.to_owned();
        if fleets.last() != Some(&fleet) {
            fleets.push(fleet);
        }
    }
    Ok(fleets)
}

impl Store {
    /// Refuses a mode on a version `fleet` does not have (0, to map, always exists).
    pub fn mode_version_exists(&self, fleet: &str, version: u64) -> Result<(), ModeError> {
        if version != 0 && self.version_summary(fleet, version)?.is_none() {
            return Err(ModeError::NoVersion {
                fleet: fleet.to_owned(),
                version,
            });
        }
        Ok(())
    }

    /// Every fleet's modes.
    pub fn modes(&self) -> Result<Vec<(String, StoredModes)>, StoreError> {
        let table = self.read_txn()?.open_table(MODES)?;
        let mut fleets: Vec<(String, StoredModes)> = Vec::new();
        for entry in table.iter()? {
            let (k, v) = entry?;
            let ((fleet, robot), version) = (k.value(), v.value());
            if fleets.last().is_none_or(|(f, _)| f != fleet) {
                fleets.push((fleet.to_owned(), StoredModes::default()));
            }
            let modes = &mut fleets.last_mut().expect("pushed").1;
            match robot {
                "" => modes.fleet = Some(version),
                _ => modes.robots.push((robot.to_owned(), version)),
            }
        }
        Ok(fleets)
    }

    /// Settings of `fleet` that localize on `version`.
    pub(super) fn version_users(&self, fleet: &str, version: u64) -> Result<usize, StoreError> {
        let table = self.read_txn()?.open_table(MODES)?;
        let mut users = 0;
        for entry in table.range((fleet, "")..=(fleet, "\u{10ffff}"))? {
            users += usize::from(entry?.1.value() == version);
        }
        Ok(users)
    }
}
