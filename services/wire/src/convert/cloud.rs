//! The segmented 3D cloud a node may carry.

use crate::error::finite;
use crate::{WireError, v1};
use leveling::{ClassCounts, PointClass};

/// The largest coordinate of a cloud point on the wire (cm): 1 km from the scan's origin.
pub const CLOUD_MAX_COORD_CM: i32 = 100_000;
/// The most points a node's cloud may carry (a full spinning 64-beam scan is about 130,000).
pub const CLOUD_MAX_POINTS: usize = 1 << 20;

/// A node's segmented 3D cloud in metres, as [`cloud_to_wire`] sends it and
/// [`cloud_from_wire`] gives it back (to the centimetre).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ClassifiedCloud {
    /// Points in the leveled frame of the node's scan (m).
    pub points_m: Vec<[f32; 3]>,
    /// The class of every point, same order; never [`PointClass::Invalid`].
    pub classes: Vec<PointClass>,
    /// Valid points of the 3D scan before the reduction.
    pub source_points: u64,
    /// Voxel edge of the reduction (m); 0: none.
    pub voxel_m: f32,
    /// The reduction's cap on points; 0: none.
    pub max_points: u32,
}

impl ClassifiedCloud {
    /// Points per class (`invalid` is 0).
    pub fn counts(&self) -> ClassCounts {
        ClassCounts::of(&self.classes)
    }
}

/// The class a cloud's class byte stands for; `None` for 0 (invalid, never sent) and
/// anything above 3.
pub fn point_class_from_wire(byte: u8) -> Option<PointClass> {
    match byte {
        1 => Some(PointClass::Ground),
        2 => Some(PointClass::Landmark),
        3 => Some(PointClass::Overhang),
        _ => None,
    }
}

/// A cloud on the wire: coordinates rounded to the centimetre. A point that the receiver
/// would reject is left out with its class: an invalid one, a non-finite coordinate, one
/// farther than [`CLOUD_MAX_COORD_CM`]; and points beyond [`CLOUD_MAX_POINTS`].
pub fn cloud_to_wire(cloud: &ClassifiedCloud) -> v1::SegmentedCloud {
    let n = cloud.classes.len().min(cloud.points_m.len());
    let n = n.min(CLOUD_MAX_POINTS);
    let mut xyz_cm = Vec::with_capacity(3 * n);
    let mut classes = Vec::with_capacity(n);
    let cm = |v: f32| {
        let c = (f64::from(v) * 100.0).round();
        (c.abs() <= f64::from(CLOUD_MAX_COORD_CM)).then_some(c as i32)
    };
    for (p, &class) in cloud.points_m.iter().zip(&cloud.classes) {
        if classes.len() == CLOUD_MAX_POINTS {
            break;
        }
        if class == PointClass::Invalid {
            continue;
        }
        if let (Some(x), Some(y), Some(z)) = (cm(p[0]), cm(p[1]), cm(p[2])) {
            xyz_cm.extend([x, y, z]);
            classes.push(class as u8);
        }
    }
    v1::SegmentedCloud {
        xyz_cm,
        classes,
        source_points: cloud.source_points,
        voxel_m: cloud.voxel_m,
        max_points: cloud.max_points,
    }
}

/// Checks a cloud from the wire and counts its points per class: three coordinates per class
/// byte, each within [`CLOUD_MAX_COORD_CM`]; every class 1 (ground), 2 (landmark) or 3
/// (overhang); at most [`CLOUD_MAX_POINTS`], `max_points` (if set) and `source_points` points;
/// a finite voxel size ≥ 0.
pub fn validate_cloud(cloud: &v1::SegmentedCloud) -> Result<ClassCounts, WireError> {
    let n = cloud.classes.len();
    if cloud.xyz_cm.len() != 3 * n {
        return Err(WireError::Invalid {
            field: "SegmentedCloud.classes",
            detail: format!(
                "{n} classes for {} coordinates (3 per point)",
                cloud.xyz_cm.len()
            ),
        });
    }
    let too_many = |field, limit: u64, what: &str| WireError::Invalid {
        field,
        detail: format!("{n} points, more than {what} ({limit})"),
    };
    if n > CLOUD_MAX_POINTS {
        let limit = CLOUD_MAX_POINTS as u64;
        return Err(too_many(
            "SegmentedCloud.classes",
            limit,
            "a node may carry",
        ));
    }
    if cloud.max_points != 0 && n > cloud.max_points as usize {
        let limit = cloud.max_points.into();
        return Err(too_many("SegmentedCloud.max_points", limit, "its cap"));
    }
    if n as u64 > cloud.source_points {
        let limit = cloud.source_points;
        return Err(too_many(
            "SegmentedCloud.source_points",
            limit,
            "its source",
        ));
    }
    let voxel = finite("SegmentedCloud.voxel_m", None, cloud.voxel_m.into())?;
    if voxel < 0.0 {
        return Err(WireError::InvalidValue {
            field: "SegmentedCloud.voxel_m",
            index: None,
            value: voxel,
            problem: "negative",
        });
    }
    let mut counts = ClassCounts::default();
    for (i, &byte) in cloud.classes.iter().enumerate() {
        match point_class_from_wire(byte) {
            Some(PointClass::Ground) => counts.ground += 1,
            Some(PointClass::Landmark) => counts.landmark += 1,
            Some(PointClass::Overhang) => counts.overhang += 1,
            Some(PointClass::Invalid) | None => {
                return Err(WireError::InvalidValue {
                    field: "SegmentedCloud.classes",
                    index: Some(i),
                    value: byte.into(),
                    problem: "not a point class (1 ground, 2 landmark, 3 overhang)",
                });
            }
        }
    }
    if let Some(i) = cloud
        .xyz_cm
        .iter()
        .position(|v| v.unsigned_abs() > CLOUD_MAX_COORD_CM.unsigned_abs())
    {
        return Err(WireError::InvalidValue {
            field: "SegmentedCloud.xyz_cm",
            index: Some(i),
            value: cloud.xyz_cm[i].into(),
            problem: "beyond 1 km (±100000 cm)",
        });
    }
    Ok(counts)
}

/// A cloud as its bytes are stored apart from its node ([`crate::split_node_cloud`]),
/// decoded and checked ([`cloud_from_wire`]).
pub fn decode_cloud(bytes: &[u8]) -> Result<ClassifiedCloud, WireError> {
    cloud_from_wire(&super::decode("SegmentedCloud", bytes)?)
}

/// A cloud from the wire, checked ([`validate_cloud`]), in metres.
pub fn cloud_from_wire(cloud: &v1::SegmentedCloud) -> Result<ClassifiedCloud, WireError> {
    validate_cloud(cloud)?;
    let m = |v: i32| (f64::from(v) / 100.0) as f32;
    Ok(ClassifiedCloud {
        points_m: cloud
            .xyz_cm
            .chunks_exact(3)
            .map(|p| [m(p[0]), m(p[1]), m(p[2])])
            .collect(),
        classes: cloud
            .classes
            .iter()
            .filter_map(|&b| point_class_from_wire(b))
            .collect(),
        source_points: cloud.source_points,
        voxel_m: cloud.voxel_m,
        max_points: cloud.max_points,
    })
}

/// A node's cloud against its scan's counts (when sent): as many source points as the scan
/// has valid ones, and no class with more points kept than the scan has.
pub(crate) fn check_cloud_against_counts(
    kept: &ClassCounts,
    cloud: &v1::SegmentedCloud,
    counts: &v1::SegmentationCounts,
) -> Result<(), WireError> {
    // The counts add up to `points` (checked before), so this sum does not overflow.
    let valid = counts.ground + counts.landmark + counts.overhang;
    if cloud.source_points != valid {
        return Err(WireError::Invalid {
            field: "Node.cloud.source_points",
            detail: format!(
                "{} source points, but the scan has {valid} valid ones",
                cloud.source_points
            ),
        });
    }
    for (name, kept, total) in [
        ("ground", kept.ground, counts.ground),
        ("landmark", kept.landmark, counts.landmark),
        ("overhang", kept.overhang, counts.overhang),
    ] {
        if kept as u64 > total {
            return Err(WireError::Invalid {
                field: "Node.cloud.classes",
                detail: format!("{kept} {name} points, but the scan has {total}"),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convert::fixtures::*;
    use crate::*;

    #[test]
    fn cloud_round_trips_to_the_centimetre() {
        let decoded = decode_node_message(&node().encode_to_vec()).unwrap();
        let wire = decoded.cloud.as_ref().unwrap();
        assert_eq!(wire.classes, [1, 2, 3, 1]);
        assert_eq!(&wire.xyz_cm[..6], [125, -50, -75, -1250, 300, 25]);
        assert_eq!(&wire.xyz_cm[9..], [99_999, -99_999, 0]);
        let back = cloud_from_wire(wire).unwrap();
        let original = cloud();
        assert_eq!(back.classes, original.classes);
        for (a, b) in back.points_m.iter().zip(&original.points_m) {
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() <= 0.005 + 1e-4, "{a:?} vs {b:?}");
            }
        }
        assert_eq!(
            (back.source_points, back.voxel_m, back.max_points),
            (26_900, 0.1, 6000)
        );
        let counts = back.counts();
        assert_eq!(
            (
                counts.ground,
                counts.landmark,
                counts.overhang,
                counts.invalid
            ),
            (2, 1, 1, 0)
        );
        assert_eq!(validate_cloud(wire).unwrap(), counts);
        // A node without a cloud is valid too, and one made before field 9 existed (its bytes
        // are the same) decodes to the same node.
        let mut n = node();
        n.cloud = None;
        assert_eq!(decode_node_message(&n.encode_to_vec()).unwrap(), n);
        // Sent without its cloud, the node is smaller by the cloud's encoding and a field tag.
        let cloud_bytes = wire.encoded_len();
        assert_eq!(
            node().encoded_len(),
            n.encoded_len() + cloud_bytes + 1 + prost::length_delimiter_len(cloud_bytes)
        );
    }

    #[test]
    fn cloud_to_wire_leaves_out_what_a_receiver_rejects() {
        let mut c = cloud();
        c.points_m.push([f32::NAN, 0.0, 0.0]);
        c.classes.push(PointClass::Landmark);
        c.points_m.push([1000.01, 0.0, 0.0]);
        c.classes.push(PointClass::Landmark);
        c.points_m.push([1.0, 1.0, 1.0]);
        c.classes.push(PointClass::Invalid);
        let wire = cloud_to_wire(&c);
        assert_eq!(wire.classes, [1, 2, 3, 1]);
        assert_eq!(wire.xyz_cm.len(), 12);
        validate_cloud(&wire).unwrap();
    }

    #[test]
    fn bad_clouds_are_rejected_with_a_reason() {
        let err = rejection(|n| {
            wire_cloud(n).xyz_cm.pop();
        });
        assert_eq!(
            err.to_string(),
            "SegmentedCloud.classes: 4 classes for 11 coordinates (3 per point)"
        );
        assert_eq!(err.reason(), "inconsistent");
        let err = rejection(|n| wire_cloud(n).classes.push(2));
        assert!(matches!(
            err,
            WireError::Invalid {
                field: "SegmentedCloud.classes",
                ..
            }
        ));
        for bad in [0u8, 4, 255] {
            let err = rejection(|n| wire_cloud(n).classes[2] = bad);
            assert_eq!(
                err,
                WireError::InvalidValue {
                    field: "SegmentedCloud.classes",
                    index: Some(2),
                    value: bad.into(),
                    problem: "not a point class (1 ground, 2 landmark, 3 overhang)",
                }
            );
            assert_eq!(err.reason(), "invalid_value");
        }
        let err = rejection(|n| wire_cloud(n).xyz_cm[7] = -100_001);
        assert_eq!(
            err.to_string(),
            "SegmentedCloud.xyz_cm[7] = -100001 is beyond 1 km (±100000 cm)"
        );
        let err = rejection(|n| wire_cloud(n).xyz_cm[0] = i32::MIN);
        assert!(matches!(
            err,
            WireError::InvalidValue { index: Some(0), .. }
        ));
        let err = rejection(|n| wire_cloud(n).voxel_m = f32::NAN);
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "SegmentedCloud.voxel_m",
                problem: "not finite",
                ..
            }
        ));
        let err = rejection(|n| wire_cloud(n).voxel_m = -0.1);
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "SegmentedCloud.voxel_m",
                problem: "negative",
                ..
            }
        ));
        let err = rejection(|n| wire_cloud(n).max_points = 3);
        assert_eq!(
            err.to_string(),
            "SegmentedCloud.max_points: 4 points, more than its cap (3)"
        );
        // max_points 0: no cap.
        let mut n = node();
        wire_cloud(&mut n).max_points = 0;
        decode_node_message(&n.encode_to_vec()).unwrap();
        // More points than the scan had, in all or in one class.
        let err = rejection(|n| wire_cloud(n).source_points = 26_901);
        assert_eq!(
            err.to_string(),
            "Node.cloud.source_points: 26901 source points, but the scan has 26900 valid ones"
        );
        let err = rejection(|n| {
            let counts = wire_scan(n).counts.as_mut().unwrap();
            (counts.overhang, counts.invalid) = (0, 2000);
        });
        assert_eq!(
            err.to_string(),
            "Node.cloud.source_points: 26900 source points, but the scan has 25000 valid ones"
        );
        let err = rejection(|n| {
            let counts = wire_scan(n).counts.as_mut().unwrap();
            (counts.overhang, counts.ground) = (0, 21_900);
        });
        assert_eq!(
            err.to_string(),
            "Node.cloud.classes: 1 overhang points, but the scan has 0"
        );
        // Without counts on the scan (a planar scanner's node) only the cloud itself is checked.
        let mut n = node();
        wire_scan(&mut n).counts = None;
        wire_cloud(&mut n).source_points = 4;
        decode_node_message(&n.encode_to_vec()).unwrap();
        wire_cloud(&mut n).source_points = 3;
        let err = decode_node_message(&n.encode_to_vec()).unwrap_err();
        assert!(matches!(
            err,
            WireError::Invalid {
                field: "SegmentedCloud.source_points",
                ..
            }
        ));
    }
}
