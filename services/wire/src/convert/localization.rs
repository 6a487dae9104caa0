//! Localization on a map version: the mapper's answer per node (and per HTTP request), and
//! the HTTP request's scan and prior.

use super::decode;
use super::pose::{pose2_from_wire, pose2_to_wire};
use super::scan::{check_beam, leveled_scan_from_wire};
use crate::error::finite;
use crate::{WIRE_VERSION, WireError, v1, validate_id};
use leveling::{Beam, LeveledScan};
use slam::Pose2;
use slam::localize::{Prior, SearchKind, TrackStatus};
use slam::matching::Scan2;

/// Where a robot's node (or a requested scan) is on a map version.
#[derive(Clone, Debug, PartialEq)]
pub struct Localized {
    /// The fleet.
    pub fleet: String,
    /// The robot ("" in an HTTP answer).
    pub robot: String,
    /// Its node's chain and number (0 in an HTTP answer).
    pub chain_id: u64,
    /// See `chain_id`.
    pub node_seq: u64,
    /// The map version.
    pub map_version: u64,
    /// Found, carried forward by odometry, or lost.
    pub status: TrackStatus,
    /// The scan frame in the map frame, unless lost.
    pub pose: Option<Pose2>,
    /// Covariance of (x, y, yaw) when found.
    pub covariance: Option<[[f64; 3]; 3]>,
    /// The correlative score when found (0–1).
    pub score: f64,
    /// The search that found it.
    pub search: Option<SearchKind>,
    /// When the mapper made it (ns since the Unix epoch).
    pub sent_ns: u64,
    /// Why not found, when not.
    pub reason: String,
}

/// A localization on the wire.
pub fn localization_to_wire(l: &Localized) -> v1::Localization {
    use v1::localization::{Search, Status};
    v1::Localization {
        version: WIRE_VERSION,
        fleet_id: l.fleet.clone(),
        robot_id: l.robot.clone(),
        chain_id: l.chain_id,
        node_seq: l.node_seq,
        map_version: l.map_version,
        status: match l.status {
            TrackStatus::Localized => Status::Localized,
            TrackStatus::DeadReckoned => Status::DeadReckoned,
            TrackStatus::Lost => Status::Lost,
        } as i32,
        pose: l.pose.as_ref().map(pose2_to_wire),
        covariance: l
            .covariance
            .map(|c| c.iter().flatten().copied().collect())
            .unwrap_or_default(),
        score: l.score,
        search: match l.search {
            None => Search::Unspecified,
            Some(SearchKind::Window) => Search::Window,
            Some(SearchKind::Global) => Search::Global,
        } as i32,
        sent_ns: l.sent_ns,
        reason: l.reason.clone(),
    }
}

/// Decodes and checks a localization: this wire version, valid ids, a known status, a
/// finite pose (required unless lost) and a finite 3×3 covariance (or none).
pub fn decode_localization(bytes: &[u8]) -> Result<Localized, WireError> {
    use v1::localization::{Search, Status};
    let msg: v1::Localization = decode("Localization", bytes)?;
    if msg.version != WIRE_VERSION {
        return Err(WireError::Version {
            field: "Localization.version",
            found: msg.version,
        });
    }
    validate_id("fleet", &msg.fleet_id)?;
    if !msg.robot_id.is_empty() {
        validate_id("robot", &msg.robot_id)?;
    }
    let invalid = |field, detail: &str| WireError::Invalid {
        field,
        detail: detail.to_owned(),
    };
    let status = match Status::try_from(msg.status) {
        Ok(Status::Localized) => TrackStatus::Localized,
        Ok(Status::DeadReckoned) => TrackStatus::DeadReckoned,
        Ok(Status::Lost) => TrackStatus::Lost,
        _ => return Err(invalid("Localization.status", "unknown status")),
    };
    let pose = msg.pose.as_ref().map(pose2_from_wire).transpose()?;
    if pose.is_none() && status != TrackStatus::Lost {
        return Err(WireError::Missing {
            field: "Localization.pose",
        });
    }
    let covariance = match msg.covariance.len() {
        0 => None,
        9 => {
            for (i, &v) in msg.covariance.iter().enumerate() {
                finite("Localization.covariance", Some(i), v)?;
            }
            Some(std::array::from_fn(|i| {
                std::array::from_fn(|j| msg.covariance[3 * i + j])
            }))
        }
        _ => return Err(invalid("Localization.covariance", "not 9 values")),
    };
    let search = match Search::try_from(msg.search) {
        Ok(Search::Window) => Some(SearchKind::Window),
        Ok(Search::Global) => Some(SearchKind::Global),
        _ => None,
    };
    Ok(Localized {
        fleet: msg.fleet_id,
        robot: msg.robot_id,
        chain_id: msg.chain_id,
        node_seq: msg.node_seq,
        map_version: msg.map_version,
        status,
        pose,
        covariance,
        score: finite("Localization.score", None, msg.score)?,
        search,
        sent_ns: msg.sent_ns,
        reason: msg.reason,
    })
}

/// A request to find a scan on a map version, checked.
#[derive(Clone, Debug, PartialEq)]
pub struct LocalizeQuery {
    /// The scan.
    pub scan: LeveledScan,
    /// The guess and its 1σ in x and y (m) and yaw (rad), if any.
    pub prior: Option<(Pose2, f64, f64)>,
    /// The map version; 0: the newest.
    pub map_version: u64,
}

impl LocalizeQuery {
    /// The scan as matching uses it, cut at `max_range_m`.
    pub fn scan2(&self, max_range_m: f32) -> Scan2 {
        matching_scan(&self.scan, max_range_m)
    }

    /// The prior as the window searched: 3σ around the guess.
    pub fn prior_window(&self) -> Option<Prior> {
        self.prior.map(|(pose, sigma_xy, sigma_yaw)| Prior {
            pose,
            linear_m: 3.0 * sigma_xy,
            angular_rad: 3.0 * sigma_yaw,
        })
    }
}

/// A leveled scan's returns as matching uses them, cut at `max_range_m`.
pub fn matching_scan(scan: &LeveledScan, max_range_m: f32) -> Scan2 {
    scan_of_returns(scan.returns(), max_range_m)
}

/// A leveled scan's beams as the grid takes them: every beam, a return or none, so that
/// neighbouring beams fill the wedge between them (`slam::grid`), each from where the sensor
/// was when it measured the beam.
pub fn grid_fan(scan: &LeveledScan) -> slam::BeamFan {
    slam::BeamFan::new(scan.beams.iter().map(|b| {
        let (bearing_rad, range_m) = b.seen_from_sensor();
        slam::FanBeam {
            from_m: b.sensor_xy_m.map(f64::from),
            bearing_rad,
            range_m,
            free_to_m: b.ground_to_m.map(f64::from),
        }
    }))
}

/// Returns (bearing in rad, range in m) as a `Scan2`, cut at `max_range_m`: the one place a
/// scan becomes what matching, the grids and localization use.
pub(crate) fn scan_of_returns(
    returns: impl Iterator<Item = (f32, f32)>,
    max_range_m: f32,
) -> Scan2 {
    let (bearings, ranges): (Vec<f32>, Vec<f32>) = returns.unzip();
    Scan2::from_polar(&bearings, &ranges, max_range_m).expect("returns come in pairs")
}

/// A prior's σ when the request gives none: 0.5 m and 0.1 rad.
pub const DEFAULT_PRIOR_SIGMA: (f64, f64) = (0.5, 0.1);

/// A prior's σ: finite and positive; none: `default`.
fn prior_sigma(field: &'static str, sigma: Option<f64>, default: f64) -> Result<f64, WireError> {
    let Some(v) = sigma else {
        return Ok(default);
    };
    let v = finite(field, None, v)?;
    if v <= 0.0 {
        return Err(WireError::Invalid {
            field,
            detail: format!("{v} is not positive"),
        });
    }
    Ok(v)
}

/// A localize request given as beams (the API's JSON): checked as a protobuf request is, each
/// beam as a leveled scan's (a finite bearing, a range from 0, no return, to 1 km), at least
/// one, as many ranges as bearings; a finite prior with σ positive (none: the defaults).
pub fn localize_query(
    bearings_rad: &[f32],
    ranges_m: &[f32],
    prior: Option<(Pose2, Option<f64>, Option<f64>)>,
    map_version: u64,
) -> Result<LocalizeQuery, WireError> {
    if bearings_rad.len() != ranges_m.len() || bearings_rad.is_empty() {
        return Err(WireError::Invalid {
            field: "ranges_m",
            detail: format!(
                "{} bearings and {} ranges: give one range per bearing, at least one",
                bearings_rad.len(),
                ranges_m.len()
            ),
        });
    }
    let beams = bearings_rad
        .iter()
        .zip(ranges_m)
        .enumerate()
        .map(|(i, (&bearing_rad, &range_m))| {
            check_beam(("bearings_rad", "ranges_m"), i, bearing_rad, range_m)?;
            Ok(Beam {
                bearing_rad,
                range_m: (range_m > 0.0).then_some(range_m),
                sensor_xy_m: [0.0, 0.0],
                ground_to_m: None,
            })
        })
        .collect::<Result<_, WireError>>()?;
    let prior = match prior {
        None => None,
        Some((pose, sigma_xy, sigma_yaw)) => {
            if !pose.is_finite() {
                return Err(WireError::Invalid {
                    field: "prior.pose",
                    detail: "not finite".into(),
                });
            }
            Some((
                pose,
                prior_sigma("prior.sigma_xy_m", sigma_xy, DEFAULT_PRIOR_SIGMA.0)?,
                prior_sigma("prior.sigma_yaw_rad", sigma_yaw, DEFAULT_PRIOR_SIGMA.1)?,
            ))
        }
    };
    Ok(LocalizeQuery {
        scan: LeveledScan { stamp_ns: 0, beams },
        prior,
        map_version,
    })
}

/// Decodes and checks a localize request: this wire version, a valid leveled scan, a finite
/// prior, σ finite and not negative (0: the default).
pub fn decode_localize_request(bytes: &[u8]) -> Result<LocalizeQuery, WireError> {
    let msg: v1::LocalizeRequest = decode("LocalizeRequest", bytes)?;
    if msg.version != WIRE_VERSION {
        return Err(WireError::Version {
            field: "LocalizeRequest.version",
            found: msg.version,
        });
    }
    let scan = msg.scan.as_ref().ok_or(WireError::Missing {
        field: "LocalizeRequest.scan",
    })?;
    let scan = leveled_scan_from_wire(scan)?;
    // On the wire 0 is "not given": the default.
    let given = |v: f64| (v != 0.0).then_some(v);
    let prior = match &msg.prior {
        None => None,
        Some(p) => Some((
            pose2_from_wire(p)?,
            prior_sigma(
                "LocalizeRequest.prior_sigma_xy_m",
                given(msg.prior_sigma_xy_m),
                DEFAULT_PRIOR_SIGMA.0,
            )?,
            prior_sigma(
                "LocalizeRequest.prior_sigma_yaw_rad",
                given(msg.prior_sigma_yaw_rad),
                DEFAULT_PRIOR_SIGMA.1,
            )?,
        )),
    };
    Ok(LocalizeQuery {
        scan,
        prior,
        map_version: msg.map_version,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Message;

    fn found() -> Localized {
        Localized {
            fleet: "park".into(),
            robot: "r4".into(),
            chain_id: 7,
            node_seq: 42,
            map_version: 1,
            status: TrackStatus::Localized,
            pose: Some(Pose2::new(1.0, -2.0, 0.5)),
            covariance: Some([[1e-4, 0.0, 0.0], [0.0, 2e-4, 1e-6], [0.0, 1e-6, 1e-5]]),
            score: 0.71,
            search: Some(SearchKind::Window),
            sent_ns: 123,
            reason: String::new(),
        }
    }

    #[test]
    fn a_localization_survives_the_wire() {
        let l = found();
        let bytes = localization_to_wire(&l).encode_to_vec();
        assert_eq!(decode_localization(&bytes).unwrap(), l);
        let lost = Localized {
            status: TrackStatus::Lost,
            pose: None,
            covariance: None,
            search: None,
            reason: "not found".into(),
            ..found()
        };
        let bytes = localization_to_wire(&lost).encode_to_vec();
        assert_eq!(decode_localization(&bytes).unwrap(), lost);
    }

    #[test]
    fn a_localize_query_of_beams_is_checked_as_a_leveled_scan_is() {
        let pose = Pose2::new(1.0, 2.0, 0.3);
        let q = localize_query(
            &[0.0, 0.1, 0.2],
            &[5.0, 0.0, 7.0],
            Some((pose, None, Some(0.2))),
            3,
        )
        .unwrap();
        assert_eq!(q.scan.beams[1].range_m, None, "0 is no return");
        assert_eq!(q.scan2(40.0).len(), 2);
        assert_eq!(q.scan2(6.0).len(), 1, "cut at the range");
        let w = q.prior_window().unwrap();
        assert_eq!((w.pose, w.linear_m, w.angular_rad), (pose, 1.5, 3.0 * 0.2));
        assert_eq!(q.map_version, 3);
        let refused = [
            localize_query(&[0.0], &[1.0, 2.0], None, 0),
            localize_query(&[], &[], None, 0),
            localize_query(&[f32::NAN], &[1.0], None, 0),
            localize_query(&[0.0], &[-1.0], None, 0),
            localize_query(&[0.0], &[2000.0], None, 0),
            localize_query(&[0.0], &[1.0], Some((pose, Some(0.0), None)), 0),
            localize_query(&[0.0], &[1.0], Some((pose, None, Some(f64::INFINITY))), 0),
            localize_query(
                &[0.0],
                &[1.0],
                Some((Pose2::new(f64::NAN, 0.0, 0.0), None, None)),
                0,
            ),
        ];
        for (i, r) in refused.iter().enumerate() {
            assert!(r.is_err(), "case {i} taken: {r:?}");
        }
    }

    #[test]
    fn a_bad_localization_is_refused() {
        let mut msg = localization_to_wire(&found());
        msg.covariance.pop();
        assert!(decode_localization(&msg.encode_to_vec()).is_err());
        let mut msg = localization_to_wire(&found());
        msg.pose = None;
        assert!(decode_localization(&msg.encode_to_vec()).is_err());
        let mut msg = localization_to_wire(&found());
        msg.robot_id = "r/*".into();
        assert!(decode_localization(&msg.encode_to_vec()).is_err());
        let mut msg = localization_to_wire(&found());
        msg.covariance[4] = f64::NAN;
        assert!(decode_localization(&msg.encode_to_vec()).is_err());
    }
}
