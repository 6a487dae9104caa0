//! The leveled scan and its segmentation counts.

use super::check_header;
use crate::error::{MAX_RANGE_M, bounded, finite};
use crate::{WireError, v1};
use leveling::{Beam, ClassCounts, LeveledScan};

/// Segmentation counts on the wire; `points` is their sum.
pub fn counts_to_wire(counts: &ClassCounts) -> v1::SegmentationCounts {
    let c = |n: usize| n as u64;
    v1::SegmentationCounts {
        points: c(counts.invalid + counts.ground + counts.landmark + counts.overhang),
        invalid: c(counts.invalid),
        ground: c(counts.ground),
        landmark: c(counts.landmark),
        overhang: c(counts.overhang),
    }
}

/// Segmentation counts from the wire; rejects counts that do not add up to `points`.
pub fn counts_from_wire(counts: &v1::SegmentationCounts) -> Result<ClassCounts, WireError> {
    let field = "SegmentationCounts.points";
    let sum = [
        counts.invalid,
        counts.ground,
        counts.landmark,
        counts.overhang,
    ]
    .into_iter()
    .try_fold(0u64, u64::checked_add);
    if sum != Some(counts.points) {
        return Err(WireError::Invalid {
            field,
            detail: format!(
                "{} points, but the classes add up to {}",
                counts.points,
                sum.map_or("more than 2^64".to_owned(), |s| s.to_string())
            ),
        });
    }
    let to_usize = |n: u64| {
        usize::try_from(n).map_err(|_| WireError::InvalidValue {
            field,
            index: None,
            value: n as f64,
            problem: "too large for this platform",
        })
    };
    to_usize(counts.points)?;
    Ok(ClassCounts {
        invalid: to_usize(counts.invalid)?,
        ground: to_usize(counts.ground)?,
        landmark: to_usize(counts.landmark)?,
        overhang: to_usize(counts.overhang)?,
    })
}

/// A leveled scan on the wire, with its class counts when known. `header.stamp_ns` is set to
/// `scan.stamp_ns` (the scan's measurement time); a beam without return is sent as range 0,
/// and `columns` is the number of beams (one per column of the 3D scan).
pub fn leveled_scan_to_wire(
    scan: &LeveledScan,
    counts: Option<&ClassCounts>,
    mut header: v1::Header,
) -> v1::LeveledScan {
    header.stamp_ns = scan.stamp_ns;
    let (bearing_rad, range_m) = scan.polar();
    // Sent only for a scan taken while moving: a still scan's are all zero.
    let (sensor_x_m, sensor_y_m) = if scan.beams.iter().any(|b| b.sensor_xy_m != [0.0, 0.0]) {
        scan.beams
            .iter()
            .map(|b| (b.sensor_xy_m[0], b.sensor_xy_m[1]))
            .unzip()
    } else {
        (Vec::new(), Vec::new())
    };
    let ground_to_m = if scan.beams.iter().any(|b| b.ground_to_m.is_some()) {
        scan.beams
            .iter()
            .map(|b| b.ground_to_m.unwrap_or(0.0))
            .collect()
    } else {
        Vec::new()
    };
    v1::LeveledScan {
        header: Some(header),
        bearing_rad,
        range_m,
        counts: counts.map(counts_to_wire),
        columns: u32::try_from(scan.beams.len()).unwrap_or(u32::MAX),
        sensor_x_m,
        sensor_y_m,
        ground_to_m,
    }
}

/// Beam `index` of a scan (its bearing and range fields named): a finite bearing, a finite
/// range from 0 (no return) to [`MAX_RANGE_M`].
pub(super) fn check_beam(
    (bearing_field, range_field): (&'static str, &'static str),
    index: usize,
    bearing_rad: f32,
    range_m: f32,
) -> Result<(), WireError> {
    finite(bearing_field, Some(index), bearing_rad.into())?;
    check_range(range_field, index, range_m)
}

/// Value `index` of a range field: finite, from 0 to [`MAX_RANGE_M`].
fn check_range(field: &'static str, index: usize, range_m: f32) -> Result<(), WireError> {
    bounded(
        field,
        Some(index),
        range_m.into(),
        MAX_RANGE_M,
        "implausible_range",
    )?;
    if range_m < 0.0 {
        return Err(WireError::InvalidValue {
            field,
            index: Some(index),
            value: range_m.into(),
            problem: "negative",
        });
    }
    Ok(())
}

/// A leveled scan from the wire, checked: header of this version, at least one beam,
/// `bearing_rad` and `range_m` of equal length and matching `columns`, counts (if present)
/// that add up, finite bearings, finite ranges ≥ 0, sensor places and ground reaches none
/// or one per beam, within [`MAX_RANGE_M`] (reaches ≥ 0). Range 0 becomes `None` (no
/// return); a beam with a return carries no ground reach.
pub fn leveled_scan_from_wire(msg: &v1::LeveledScan) -> Result<LeveledScan, WireError> {
    let header = check_header(msg.header.as_ref(), "LeveledScan.header")?;
    let n = msg.bearing_rad.len();
    if msg.range_m.len() != n {
        return Err(WireError::Invalid {
            field: "LeveledScan.range_m",
            detail: format!("{} ranges for {n} bearings", msg.range_m.len()),
        });
    }
    if n == 0 {
        return Err(WireError::Invalid {
            field: "LeveledScan.bearing_rad",
            detail: "the scan has no beams".to_owned(),
        });
    }
    if u32::try_from(n) != Ok(msg.columns) {
        return Err(WireError::Invalid {
            field: "LeveledScan.columns",
            detail: format!("{} columns but {n} beams", msg.columns),
        });
    }
    if let Some(counts) = &msg.counts {
        counts_from_wire(counts)?;
    }
    let moving = !(msg.sensor_x_m.is_empty() && msg.sensor_y_m.is_empty());
    for (field, places) in [
        ("LeveledScan.sensor_x_m", &msg.sensor_x_m),
        ("LeveledScan.sensor_y_m", &msg.sensor_y_m),
    ] {
        if moving && places.len() != n {
            return Err(WireError::Invalid {
                field,
                detail: format!("{} sensor places for {n} beams", places.len()),
            });
        }
        for (i, &v) in places.iter().enumerate() {
            bounded(field, Some(i), v.into(), MAX_RANGE_M, "implausible_range")?;
        }
    }
    if !msg.ground_to_m.is_empty() && msg.ground_to_m.len() != n {
        return Err(WireError::Invalid {
            field: "LeveledScan.ground_to_m",
            detail: format!("{} ground reaches for {n} beams", msg.ground_to_m.len()),
        });
    }
    for (i, &v) in msg.ground_to_m.iter().enumerate() {
        check_range("LeveledScan.ground_to_m", i, v)?;
    }
    let ground_to = |i: usize| msg.ground_to_m.get(i).copied();
    let sensor = |i: usize| {
        if moving {
            [msg.sensor_x_m[i], msg.sensor_y_m[i]]
        } else {
            [0.0, 0.0]
        }
    };
    let beams = msg
        .bearing_rad
        .iter()
        .zip(&msg.range_m)
        .enumerate()
        .map(|(i, (&bearing_rad, &range_m))| {
            check_beam(
                ("LeveledScan.bearing_rad", "LeveledScan.range_m"),
                i,
                bearing_rad,
                range_m,
            )?;
            Ok(Beam {
                bearing_rad,
                range_m: (range_m > 0.0).then_some(range_m),
                sensor_xy_m: sensor(i),
                ground_to_m: if range_m > 0.0 { None } else { ground_to(i) },
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(LeveledScan {
        stamp_ns: header.stamp_ns,
        beams,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convert::fixtures::*;
    use crate::*;

    #[test]
    fn leveled_scan_round_trips_through_bytes() {
        let original = scan();
        let bytes = node().encode_to_vec();
        let decoded = decode_node_message(&bytes).unwrap();
        let wire = decoded.scan.as_ref().unwrap();
        assert_eq!(wire.columns, 360);
        assert_eq!(wire.header.as_ref().unwrap().stamp_ns, STAMP_NS);
        let back = leveled_scan_from_wire(wire).unwrap();
        assert_eq!(back, original);
        assert_eq!(back.beams[0].range_m, None);
        assert_eq!(back.return_count(), original.return_count());
        assert_eq!(
            counts_from_wire(wire.counts.as_ref().unwrap()).unwrap(),
            counts()
        );
        assert_eq!(wire.counts.unwrap().points, 27_000);
        assert_eq!(decoded.node_seq, 7);
        assert_eq!(decoded, node());
    }

    #[test]
    fn nan_and_negative_ranges_are_rejected_with_field_and_index() {
        let err = rejection(|n| wire_scan(n).range_m[17] = f32::NAN);
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "LeveledScan.range_m",
                index: Some(17),
                problem: "not finite",
                ..
            }
        ));
        assert_eq!(
            err.to_string(),
            "LeveledScan.range_m[17] = NaN is not finite"
        );
        let err = rejection(|n| wire_scan(n).range_m[3] = -1.0);
        assert_eq!(err.to_string(), "LeveledScan.range_m[3] = -1 is negative");
        let err = rejection(|n| wire_scan(n).range_m[5] = f32::INFINITY);
        assert!(matches!(
            err,
            WireError::InvalidValue { index: Some(5), .. }
        ));
        let err = rejection(|n| wire_scan(n).bearing_rad[359] = f32::NAN);
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "LeveledScan.bearing_rad",
                index: Some(359),
                ..
            }
        ));
    }

    #[test]
    fn inconsistent_scans_are_rejected() {
        let err = rejection(|n| {
            wire_scan(n).range_m.pop();
        });
        assert_eq!(
            err.to_string(),
            "LeveledScan.range_m: 359 ranges for 360 bearings"
        );
        let err = rejection(|n| wire_scan(n).columns = 361);
        assert!(matches!(
            err,
            WireError::Invalid {
                field: "LeveledScan.columns",
                ..
            }
        ));
        let err = rejection(|n| {
            let s = wire_scan(n);
            (s.bearing_rad, s.range_m, s.columns) = (vec![], vec![], 0);
        });
        assert!(matches!(
            err,
            WireError::Invalid {
                field: "LeveledScan.bearing_rad",
                ..
            }
        ));
        let err = rejection(|n| wire_scan(n).counts.as_mut().unwrap().ground += 1);
        assert!(matches!(
            err,
            WireError::Invalid {
                field: "SegmentationCounts.points",
                ..
            }
        ));
        let err = rejection(|n| wire_scan(n).counts.as_mut().unwrap().overhang = u64::MAX);
        assert!(err.to_string().contains("more than 2^64"), "{err}");
    }

    #[test]
    fn sensor_places_go_only_with_a_moving_scan_and_are_checked() {
        let still = leveled_scan_to_wire(&scan(), None, header(1));
        assert!(still.sensor_x_m.is_empty() && still.sensor_y_m.is_empty());
        let mut moving = scan();
        for (i, beam) in moving.beams.iter_mut().enumerate() {
            beam.sensor_xy_m = [i as f32 * 0.01, -0.5];
            if beam.range_m.is_none() {
                beam.ground_to_m = Some(4.5);
            }
        }
        let wire = leveled_scan_to_wire(&moving, None, header(1));
        assert_eq!(wire.sensor_x_m.len(), 360);
        assert_eq!(wire.ground_to_m.len(), 360);
        assert_eq!(leveled_scan_from_wire(&wire).unwrap(), moving);
        let err = rejection(|n| wire_scan(n).ground_to_m = vec![1.0; 359]);
        assert_eq!(
            err.to_string(),
            "LeveledScan.ground_to_m: 359 ground reaches for 360 beams"
        );
        let err = rejection(|n| {
            let s = wire_scan(n);
            s.ground_to_m = vec![1.0; 360];
            s.ground_to_m[8] = -2.0;
        });
        assert_eq!(
            err.to_string(),
            "LeveledScan.ground_to_m[8] = -2 is negative"
        );

        let err = rejection(|n| wire_scan(n).sensor_x_m = vec![0.5; 360]);
        assert_eq!(
            err.to_string(),
            "LeveledScan.sensor_y_m: 0 sensor places for 360 beams"
        );
        let err = rejection(|n| {
            let s = wire_scan(n);
            (s.sensor_x_m, s.sensor_y_m) = (vec![0.5; 360], vec![0.0; 360]);
            s.sensor_y_m[42] = f32::NAN;
        });
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "LeveledScan.sensor_y_m",
                index: Some(42),
                ..
            }
        ));
    }
}
