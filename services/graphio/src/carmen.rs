//! CARMEN logs (`.clf`, `.log`, optionally compressed as `.gz` or `.bz2`): laser scans and
//! odometry, as the Radish / Freiburg SLAM benchmark logs store them.
//!
//! Messages read (one per line, fields separated by white space):
//! - `FLASER n r_1 … r_n x y theta odom_x odom_y odom_theta ipc_timestamp ipc_hostname
//!   logger_timestamp`: a front laser scan over 180°; `x y theta` is the laser's pose,
//!   `odom_*` the robot's (both raw odometry in the raw logs; both the SLAM-corrected pose in
//!   the "corrected" logs).
//! - `ROBOTLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode n
//!   r_1 … r_n n_rem rem_1 … rem_nrem laser_x laser_y laser_theta robot_x robot_y robot_theta
//!   tv rv forward_safety side_safety turn_axis ipc_timestamp ipc_hostname logger_timestamp`.
//! - `ODOM x y theta tv rv accel ipc_timestamp ipc_hostname logger_timestamp`.
//!
//! Everything else is counted and skipped: comments (`#`), `PARAM` (except the front laser's
//! maximum range), `SYNC`, `NEFF`, `RLASER`, `TRUEPOS`, … Unknown message types are
//! tolerated; a malformed known message is an error naming the file and line (`path:line:
//! message`) unless [`ReadOptions::skip_bad_lines`] asks to skip and report it.
//!
//! **FLASER bearings.** The message has no angles. Beam i is at `−π/2 + i·step` in the laser
//! frame (x forward, y left, counter-clockwise), with CARMEN's own step
//! (`carmen_laser_get_angle_increment`): 1° for 180 or 181 beams, 0.5° for 360 or 361,
//! 0.25° for 400 or 401, else π/(n − 1). So 180 and 360 beams end half a step short of +90°.
//! [`FlaserBearings`] selects the alternatives. The test `flaser_bearing_convention` in
//! `tests/carmen_idc.rs` checks the choice by scan matching: with the wrong step, turns match
//! with a scale error of 1/n; CARMEN's step agrees best with the corrected poses of four
//! corrected logs of five (all but Freiburg 079, whose turns carry a bias of their own).

use crate::FileError;
use slam::Pose2;
use std::collections::BTreeMap;
use std::f64::consts::{FRAC_PI_2, PI};
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// One laser scan.
#[derive(Clone, Debug, PartialEq)]
pub struct LaserScan {
    /// `ipc_timestamp` (s): the time the relations files refer to.
    pub stamp_s: f64,
    /// `logger_timestamp` (s since the logger started).
    pub logger_stamp_s: f64,
    /// Bearing of beam 0 in the laser frame (rad, counter-clockwise from x forward).
    pub first_bearing_rad: f64,
    /// Bearing increment from one beam to the next (rad).
    pub bearing_step_rad: f64,
    /// Range of every beam, in beam order (m). A value ≥ `max_range_m` (or ≤ 0) is no return.
    pub ranges_m: Vec<f32>,
    /// Ranges at or beyond this are no return (m): ROBOTLASER1's own field; for FLASER the
    /// log's `robot_front_laser_max` parameter, else [`ReadOptions::flaser_max_range_m`].
    pub max_range_m: f32,
    /// The pose the log gives for the laser (m, rad).
    pub laser_pose: Pose2,
    /// The pose the log gives for the robot: odometry in raw logs, the corrected pose in the
    /// corrected logs (m, rad).
    pub odom_pose: Pose2,
}

impl LaserScan {
    /// The scan as a point set for scan matching (returns at or beyond the maximum range
    /// dropped).
    pub fn to_scan2(&self) -> slam::matching::Scan2 {
        slam::matching::Scan2::from_polar(&self.bearings_rad(), &self.ranges_m, self.max_range_m)
            .expect("one bearing per range by construction")
    }

    /// Bearing of every beam (rad), for [`slam::matching::Scan2::from_polar`].
    pub fn bearings_rad(&self) -> Vec<f32> {
        (0..self.ranges_m.len())
            .map(|i| (self.first_bearing_rad + self.bearing_step_rad * i as f64) as f32)
            .collect()
    }
}

/// One odometry reading.
#[derive(Clone, Debug, PartialEq)]
pub struct Odometry {
    /// `ipc_timestamp` (s).
    pub stamp_s: f64,
    /// `logger_timestamp` (s).
    pub logger_stamp_s: f64,
    /// Dead-reckoned pose (m, rad).
    pub pose: Pose2,
    /// Translational velocity (m/s).
    pub tv_m_s: f64,
    /// Rotational velocity (rad/s).
    pub rv_rad_s: f64,
}

/// The contents of one log, in file order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CarmenLog {
    /// FLASER and ROBOTLASER1 messages.
    pub scans: Vec<LaserScan>,
    /// ODOM messages.
    pub odometry: Vec<Odometry>,
    /// Lines of other message types, by type (`PARAM`, `NEFF`, …); comments not counted.
    pub skipped_messages: BTreeMap<String, usize>,
    /// Malformed lines skipped under [`ReadOptions::skip_bad_lines`]; empty otherwise.
    pub bad_lines: Vec<BadLine>,
}

/// A malformed line that was skipped.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BadLine {
    /// Line number (1-based).
    pub line: usize,
    /// What is wrong with it.
    pub message: String,
}

/// How FLASER beams are spread over their 180° (beam 0 at −90° in every case).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FlaserBearings {
    /// CARMEN's step: 1° for 180/181 beams, 0.5° for 360/361, 0.25° for 400/401, else
    /// π/(n − 1).
    #[default]
    Carmen,
    /// π/n for every n.
    PiOverN,
    /// π/(n − 1) for every n: the last beam at +90°.
    PiOverNMinusOne,
}

impl FlaserBearings {
    /// The step between beams (rad) for `n` beams.
    pub fn step_rad(self, n: usize) -> f64 {
        let n = n as f64;
        match self {
            FlaserBearings::Carmen => match n as usize {
                180 | 181 => PI / 180.0,
                360 | 361 => PI / 360.0,
                400 | 401 => PI / 720.0,
                _ => PI / (n - 1.0).max(1.0),
            },
            FlaserBearings::PiOverN => PI / n.max(1.0),
            FlaserBearings::PiOverNMinusOne => PI / (n - 1.0).max(1.0),
        }
    }
}

/// Options of the reader.
#[derive(Clone, Debug, PartialEq)]
pub struct ReadOptions {
    /// Bearing convention of FLASER scans. Default [`FlaserBearings::Carmen`].
    pub flaser_bearings: FlaserBearings,
    /// Maximum range of FLASER scans when the log has no `robot_front_laser_max` parameter
    /// before them (m). Default 50: the ACES log clips at 50.00, the Intel log marks no
    /// return with 81.83.
    pub flaser_max_range_m: f32,
    /// Skip malformed lines (collected in [`CarmenLog::bad_lines`]) instead of failing on the
    /// first. Default false: no data is dropped silently.
    pub skip_bad_lines: bool,
}

impl Default for ReadOptions {
    fn default() -> ReadOptions {
        ReadOptions {
            flaser_bearings: FlaserBearings::Carmen,
            flaser_max_range_m: 50.0,
            skip_bad_lines: false,
        }
    }
}

/// Reads a CARMEN log, decompressing by extension (`.gz`, `.bz2`; anything else is plain
/// text), with default options.
pub fn read(path: &Path) -> Result<CarmenLog, FileError> {
    read_with(path, &ReadOptions::default())
}

/// Reads a CARMEN log with the given options.
pub fn read_with(path: &Path, options: &ReadOptions) -> Result<CarmenLog, FileError> {
    let reader = open_decompressed(path)?;
    parse(reader, path, options)
}

/// Opens a file for reading, decompressing `.gz` (all members) and `.bz2` (all streams).
/// Shared with the relations reader.
pub(crate) fn open_decompressed(path: &Path) -> Result<Box<dyn BufRead>, FileError> {
    let file = File::open(path).map_err(|source| FileError::Io {
        path: path.to_owned(),
        error: source,
    })?;
    let raw: Box<dyn Read> = match path.extension().and_then(|e| e.to_str()) {
        Some("gz") => Box::new(flate2::read::MultiGzDecoder::new(BufReader::new(file))),
        Some("bz2") => Box::new(bzip2::read::MultiBzDecoder::new(BufReader::new(file))),
        _ => Box::new(file),
    };
    Ok(Box::new(BufReader::with_capacity(1 << 16, raw)))
}

/// Parses a log from `reader`; `path` names it in errors.
pub fn parse(
    reader: impl BufRead,
    path: &Path,
    options: &ReadOptions,
) -> Result<CarmenLog, FileError> {
    let mut log = CarmenLog::default();
    let mut flaser_max_range_m = options.flaser_max_range_m;
    let mut lines = 0;
    for_each_line(reader, path, |number, line| {
        lines = number;
        let fields: Vec<&str> = line.split_ascii_whitespace().collect();
        let Some(&kind) = fields.first() else {
            return Ok(());
        };
        if kind.starts_with('#') {
            return Ok(());
        }
        let parsed = match kind {
            "FLASER" => flaser(&fields, options.flaser_bearings, flaser_max_range_m)
                .map(|s| log.scans.push(s)),
            "ROBOTLASER1" => robotlaser1(&fields).map(|s| log.scans.push(s)),
            "ODOM" => odom(&fields).map(|o| log.odometry.push(o)),
            _ => {
                if kind == "PARAM" && fields.get(1) == Some(&"robot_front_laser_max") {
                    match Fields::new(&fields).number(2, "robot_front_laser_max") {
                        Ok(max) => flaser_max_range_m = max as f32,
                        Err(message) => return bad_line(&mut log, path, number, message, options),
                    }
                }
                *log.skipped_messages.entry(kind.to_owned()).or_default() += 1;
                Ok(())
            }
        };
        match parsed {
            Ok(()) => Ok(()),
            Err(message) => bad_line(&mut log, path, number, message, options),
        }
    })?;
    if lines == 0 {
        return Err(FileError::Invalid {
            path: path.to_owned(),
            message: "empty log".to_string(),
        });
    }
    Ok(log)
}

/// Calls `each(line_number, line)` for every line (1-based), naming the file and line when
/// reading fails (I/O, a corrupt or truncated compressed stream, invalid UTF-8).
pub(crate) fn for_each_line(
    mut reader: impl BufRead,
    path: &Path,
    mut each: impl FnMut(usize, &str) -> Result<(), FileError>,
) -> Result<(), FileError> {
    let mut buf = Vec::new();
    let mut number = 0;
    loop {
        buf.clear();
        let n = reader
            .read_until(b'\n', &mut buf)
            .map_err(|source| FileError::Io {
                path: path.to_owned(),
                error: std::io::Error::new(source.kind(), format!("after line {number}: {source}")),
            })?;
        if n == 0 {
            return Ok(());
        }
        number += 1;
        let line = std::str::from_utf8(&buf).map_err(|_| FileError::Line {
            path: path.to_owned(),
            line: number,
            message: "not UTF-8 text".into(),
        })?;
        each(number, line)?;
    }
}

fn bad_line(
    log: &mut CarmenLog,
    path: &Path,
    line: usize,
    message: String,
    options: &ReadOptions,
) -> Result<(), FileError> {
    if options.skip_bad_lines {
        log.bad_lines.push(BadLine { line, message });
        Ok(())
    } else {
        Err(FileError::Line {
            path: path.to_owned(),
            line,
            message,
        })
    }
}

fn flaser(
    fields: &[&str],
    bearings: FlaserBearings,
    max_range_m: f32,
) -> Result<LaserScan, String> {
    let f = Fields::new(fields);
    let n = f.count(1, "num_readings")?;
    f.expect_len(n + 11)?;
    let ranges_m = f.ranges(2, n)?;
    let at = 2 + n;
    Ok(LaserScan {
        stamp_s: f.number(at + 6, "ipc_timestamp")?,
        logger_stamp_s: f.number(at + 8, "logger_timestamp")?,
        first_bearing_rad: -FRAC_PI_2,
        bearing_step_rad: bearings.step_rad(n),
        ranges_m,
        max_range_m,
        laser_pose: f.pose(at, "x y theta")?,
        odom_pose: f.pose(at + 3, "odom_x odom_y odom_theta")?,
    })
}

fn robotlaser1(fields: &[&str]) -> Result<LaserScan, String> {
    let f = Fields::new(fields);
    let n = f.count(8, "num_readings")?;
    let remissions = f.count(9 + n, "num_remissions")?;
    f.expect_len(n + remissions + 24)?;
    let at = 10 + n + remissions;
    Ok(LaserScan {
        stamp_s: f.number(at + 11, "ipc_timestamp")?,
        logger_stamp_s: f.number(at + 13, "logger_timestamp")?,
        first_bearing_rad: f.number(2, "start_angle")?,
        bearing_step_rad: f.number(4, "angular_resolution")?,
        ranges_m: f.ranges(9, n)?,
        max_range_m: f.number(5, "maximum_range")? as f32,
        laser_pose: f.pose(at, "laser_pose")?,
        odom_pose: f.pose(at + 3, "robot_pose")?,
    })
}

fn odom(fields: &[&str]) -> Result<Odometry, String> {
    let f = Fields::new(fields);
    f.expect_len(10)?;
    Ok(Odometry {
        stamp_s: f.number(7, "ipc_timestamp")?,
        logger_stamp_s: f.number(9, "logger_timestamp")?,
        pose: f.pose(1, "x y theta")?,
        tv_m_s: f.number(4, "tv")?,
        rv_rad_s: f.number(5, "rv")?,
    })
}

/// The fields of one message (the message name first), with errors that name the message
/// and the field.
struct Fields<'a, 'b> {
    kind: &'b str,
    fields: &'a [&'b str],
}

impl<'a, 'b> Fields<'a, 'b> {
    fn new(fields: &'a [&'b str]) -> Fields<'a, 'b> {
        Fields {
            kind: fields.first().copied().unwrap_or(""),
            fields,
        }
    }

    fn get(&self, i: usize, name: &str) -> Result<&'b str, String> {
        self.fields.get(i).copied().ok_or_else(|| {
            format!(
                "{}: truncated: no {name} (field {i}; the line has {} fields)",
                self.kind,
                self.fields.len()
            )
        })
    }

    /// A finite number: NaN and infinities are refused, as is anything that is not a number.
    fn number(&self, i: usize, name: &str) -> Result<f64, String> {
        let text = self.get(i, name)?;
        match text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => Err(format!(
                "{}: {name} (field {i}) is not finite: {text:?}",
                self.kind
            )),
            Err(_) => Err(format!(
                "{}: {name} (field {i}) is not a number: {text:?}",
                self.kind
            )),
        }
    }

    /// A count of the fields that follow: never more than the line has, so that the field
    /// positions computed from counts cannot overflow.
    fn count(&self, i: usize, name: &str) -> Result<usize, String> {
        let text = self.get(i, name)?;
        let n = text
            .parse::<usize>()
            .map_err(|_| format!("{}: {name} (field {i}) is not a count: {text:?}", self.kind))?;
        if n > self.fields.len() {
            return Err(format!(
                "{}: truncated: {name} (field {i}) is {n}, more than the line's {} fields",
                self.kind,
                self.fields.len()
            ));
        }
        Ok(n)
    }

    fn pose(&self, i: usize, name: &str) -> Result<Pose2, String> {
        Ok(Pose2::new(
            self.number(i, name)?,
            self.number(i + 1, name)?,
            self.number(i + 2, name)?,
        ))
    }

    fn ranges(&self, from: usize, n: usize) -> Result<Vec<f32>, String> {
        (from..from + n)
            .map(|i| self.number(i, "range").map(|r| r as f32))
            .collect()
    }

    fn expect_len(&self, len: usize) -> Result<(), String> {
        match self.fields.len() {
            l if l == len => Ok(()),
            l if l < len => Err(format!(
                "{}: truncated: {l} fields, {len} expected",
                self.kind
            )),
            l => Err(format!("{}: {l} fields, {len} expected", self.kind)),
        }
    }
}

#[cfg(test)]
mod tests;
