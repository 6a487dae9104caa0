//! Conversions between the wire messages and the `leveling` types, and the checks every
//! received message passes before anything downstream sees it.

use crate::error::finite;
use crate::{Message, WIRE_VERSION, WireError, v1, validate_id};
use leveling::nalgebra::{Isometry2, Isometry3, Quaternion, Translation3, UnitQuaternion};
use leveling::{Beam, ClassCounts, LeveledScan, PointClass, TimedPose, heading_rad};

/// Returns the header if it is present, of [`WIRE_VERSION`], with valid fleet and robot ids.
/// `field` names it in errors (`"Node.header"`).
pub fn check_header<'a>(
    header: Option<&'a v1::Header>,
    field: &'static str,
) -> Result<&'a v1::Header, WireError> {
    let header = header.ok_or(WireError::Missing { field })?;
    if header.version != WIRE_VERSION {
        return Err(WireError::Version {
            field,
            found: header.version,
        });
    }
    validate_id("fleet", &header.fleet_id)?;
    validate_id("robot", &header.robot_id)?;
    Ok(header)
}

/// A nested message must come from the same fleet and robot as the message holding it.
fn same_sender(
    outer: &v1::Header,
    inner: &v1::Header,
    field: &'static str,
) -> Result<(), WireError> {
    if outer.fleet_id == inner.fleet_id && outer.robot_id == inner.robot_id {
        Ok(())
    } else {
        Err(WireError::Invalid {
            field,
            detail: format!(
                "sender {}/{} differs from the enclosing message's {}/{}",
                inner.fleet_id, inner.robot_id, outer.fleet_id, outer.robot_id
            ),
        })
    }
}

fn decode<M: Message + Default>(message: &'static str, bytes: &[u8]) -> Result<M, WireError> {
    M::decode(bytes).map_err(|source| WireError::Decode { message, source })
}

// ---- leveled scan ----------------------------------------------------------------------

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

/// A leveled scan on the wire. `header.stamp_ns` is set to `scan.stamp_ns` (the scan's
/// measurement time); a beam without return is sent as range 0, and `columns` is the number
/// of beams (one per column of the 3D scan).
pub fn leveled_scan_to_wire(
    scan: &LeveledScan,
    counts: &ClassCounts,
    mut header: v1::Header,
) -> v1::LeveledScan {
    header.stamp_ns = scan.stamp_ns;
    v1::LeveledScan {
        header: Some(header),
        bearing_rad: scan.beams.iter().map(|b| b.bearing_rad).collect(),
        range_m: scan
            .beams
            .iter()
            .map(|b| b.range_m.unwrap_or(0.0))
            .collect(),
        counts: Some(counts_to_wire(counts)),
        columns: u32::try_from(scan.beams.len()).unwrap_or(u32::MAX),
    }
}

/// A leveled scan from the wire, checked: header of this version, at least one beam,
/// `bearing_rad` and `range_m` of equal length and matching `columns`, counts (if present)
/// that add up, finite bearings, finite ranges ≥ 0. Range 0 becomes `None` (no return).
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
    let beams = msg
        .bearing_rad
        .iter()
        .zip(&msg.range_m)
        .enumerate()
        .map(|(i, (&bearing_rad, &range_m))| {
            finite("LeveledScan.bearing_rad", Some(i), bearing_rad.into())?;
            finite("LeveledScan.range_m", Some(i), range_m.into())?;
            if range_m < 0.0 {
                return Err(WireError::InvalidValue {
                    field: "LeveledScan.range_m",
                    index: Some(i),
                    value: range_m.into(),
                    problem: "negative",
                });
            }
            Ok(Beam {
                bearing_rad,
                range_m: (range_m > 0.0).then_some(range_m),
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(LeveledScan {
        stamp_ns: header.stamp_ns,
        beams,
    })
}

// ---- segmented cloud -------------------------------------------------------------------

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
fn check_cloud_against_counts(
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

// ---- poses -----------------------------------------------------------------------------

/// A 3D pose on the wire (position in m, unit quaternion w, x, y, z).
pub fn pose3d_to_wire(pose: &Isometry3<f64>) -> v1::Pose3D {
    let t = &pose.translation.vector;
    let q = pose.rotation.quaternion();
    v1::Pose3D {
        x_m: t.x,
        y_m: t.y,
        z_m: t.z,
        qw: q.w,
        qx: q.i,
        qy: q.j,
        qz: q.k,
    }
}

/// A 3D pose from the wire: every component finite, the quaternion non-zero (normalized
/// here; an unset orientation is all zeros and therefore rejected).
pub fn pose3d_from_wire(pose: &v1::Pose3D) -> Result<Isometry3<f64>, WireError> {
    let x = finite("Pose3D.x_m", None, pose.x_m)?;
    let y = finite("Pose3D.y_m", None, pose.y_m)?;
    let z = finite("Pose3D.z_m", None, pose.z_m)?;
    let q = Quaternion::new(
        finite("Pose3D.qw", None, pose.qw)?,
        finite("Pose3D.qx", None, pose.qx)?,
        finite("Pose3D.qy", None, pose.qy)?,
        finite("Pose3D.qz", None, pose.qz)?,
    );
    let norm = q.norm();
    // Components are finite, so the norm is too.
    if norm <= 1e-6 {
        return Err(WireError::InvalidValue {
            field: "Pose3D.qw",
            index: None,
            value: norm,
            problem: "the norm of a quaternion that cannot be normalized",
        });
    }
    Ok(Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_quaternion(q),
    ))
}

/// The planar pose of a 3D pose: x, y and the heading of its x axis
/// ([`leveling::heading_rad`]), as the 2D mapping uses it.
pub fn pose2d_to_wire(pose: &Isometry3<f64>) -> v1::Pose2D {
    v1::Pose2D {
        x_m: pose.translation.vector.x,
        y_m: pose.translation.vector.y,
        yaw_rad: heading_rad(&pose.rotation),
    }
}

/// A planar pose from the wire, every component finite.
pub fn pose2d_from_wire(pose: &v1::Pose2D) -> Result<Isometry2<f64>, WireError> {
    Ok(Isometry2::new(
        [
            finite("Pose2D.x_m", None, pose.x_m)?,
            finite("Pose2D.y_m", None, pose.y_m)?,
        ]
        .into(),
        finite("Pose2D.yaw_rad", None, pose.yaw_rad)?,
    ))
}

fn check_vec3(v: Option<&v1::Vec3>, field: &'static str) -> Result<(), WireError> {
    if let Some(v) = v {
        for (i, c) in [v.x, v.y, v.z].into_iter().enumerate() {
            finite(field, Some(i), c)?;
        }
    }
    Ok(())
}

/// A covariance: either empty (unknown) or `dim`² finite values with a non-negative diagonal.
fn check_covariance(values: &[f64], dim: usize, field: &'static str) -> Result<(), WireError> {
    if !values.is_empty() && values.len() != dim * dim {
        return Err(WireError::Invalid {
            field,
            detail: format!("{} values, expected {} or none", values.len(), dim * dim),
        });
    }
    for (i, &v) in values.iter().enumerate() {
        finite(field, Some(i), v)?;
        if i % (dim + 1) == 0 && v < 0.0 {
            return Err(WireError::InvalidValue {
                field,
                index: Some(i),
                value: v,
                problem: "a negative variance",
            });
        }
    }
    Ok(())
}

// ---- odometry --------------------------------------------------------------------------

/// Odometry on the wire: `header.stamp_ns` is set to the pose's time, `pose` and `pose2d`
/// are filled; velocities and covariance are left unknown for the caller to set.
pub fn odometry_to_wire(pose: &TimedPose, mut header: v1::Header) -> v1::Odometry {
    header.stamp_ns = pose.stamp_ns;
    v1::Odometry {
        header: Some(header),
        pose: Some(pose3d_to_wire(&pose.pose)),
        pose2d: Some(pose2d_to_wire(&pose.pose)),
        linear_velocity_mps: None,
        angular_velocity_radps: None,
        pose_covariance: Vec::new(),
    }
}

/// The timed pose of an odometry message, checked: header, a valid pose, finite `pose2d`
/// and velocities if present, a covariance of 36 finite values or none.
pub fn odometry_from_wire(msg: &v1::Odometry) -> Result<TimedPose, WireError> {
    let header = check_header(msg.header.as_ref(), "Odometry.header")?;
    let pose = msg.pose.as_ref().ok_or(WireError::Missing {
        field: "Odometry.pose",
    })?;
    let pose = pose3d_from_wire(pose)?;
    if let Some(p) = &msg.pose2d {
        pose2d_from_wire(p)?;
    }
    check_vec3(
        msg.linear_velocity_mps.as_ref(),
        "Odometry.linear_velocity_mps",
    )?;
    check_vec3(
        msg.angular_velocity_radps.as_ref(),
        "Odometry.angular_velocity_radps",
    )?;
    check_covariance(&msg.pose_covariance, 6, "Odometry.pose_covariance")?;
    Ok(TimedPose {
        stamp_ns: header.stamp_ns,
        pose,
    })
}

// ---- GPS, node, ack --------------------------------------------------------------------

/// Checks a GPS fix: header, WGS84 latitude in [-90, 90] and longitude in [-180, 180]°,
/// finite altitude and lever arm, a known status, a covariance of 9 values or none.
pub fn validate_gps_fix(fix: &v1::GpsFix) -> Result<(), WireError> {
    check_header(fix.header.as_ref(), "GpsFix.header")?;
    let in_range = |field, value: f64, limit: f64| {
        finite(field, None, value)?;
        if value.abs() > limit {
            return Err(WireError::InvalidValue {
                field,
                index: None,
                value,
                problem: "out of range",
            });
        }
        Ok(())
    };
    in_range("GpsFix.latitude_deg", fix.latitude_deg, 90.0)?;
    in_range("GpsFix.longitude_deg", fix.longitude_deg, 180.0)?;
    finite("GpsFix.altitude_m", None, fix.altitude_m)?;
    check_covariance(
        &fix.position_covariance_m2,
        3,
        "GpsFix.position_covariance_m2",
    )?;
    if v1::FixStatus::try_from(fix.status).is_err() {
        return Err(WireError::InvalidValue {
            field: "GpsFix.status",
            index: None,
            value: fix.status.into(),
            problem: "not a FixStatus",
        });
    }
    check_vec3(fix.antenna_offset_m.as_ref(), "GpsFix.antenna_offset_m")
}

/// Checks a node: header; a scan and odometry, valid, from the same fleet and robot; the GPS
/// fixes and the odometry delta, if present, valid; `earlier_gps` only beside `gps`, oldest
/// first, each stamped before `gps`; the cloud, if present, valid ([`validate_cloud`]) and
/// consistent with the scan's counts.
pub fn validate_node(node: &v1::Node) -> Result<(), WireError> {
    let header = check_header(node.header.as_ref(), "Node.header")?;
    let scan = node
        .scan
        .as_ref()
        .ok_or(WireError::Missing { field: "Node.scan" })?;
    leveled_scan_from_wire(scan)?;
    let odometry = node.odometry.as_ref().ok_or(WireError::Missing {
        field: "Node.odometry",
    })?;
    odometry_from_wire(odometry)?;
    // Both checked above, so present.
    if let (Some(s), Some(o)) = (&scan.header, &odometry.header) {
        same_sender(header, s, "Node.scan.header")?;
        same_sender(header, o, "Node.odometry.header")?;
    }
    if let Some(gps) = &node.gps {
        validate_gps_fix(gps)?;
        if let Some(g) = &gps.header {
            same_sender(header, g, "Node.gps.header")?;
        }
    }
    validate_earlier_gps(header, node)?;
    if let Some(cloud) = &node.cloud {
        let kept = validate_cloud(cloud)?;
        if let Some(counts) = &scan.counts {
            check_cloud_against_counts(&kept, cloud, counts)?;
        }
    }
    for pose in [
        &node.odometry_delta_from_previous,
        &node.scan_origin_in_robot,
    ]
    .into_iter()
    .flatten()
    {
        pose2d_from_wire(pose)?;
    }
    Ok(())
}

/// Checks `Node.earlier_gps`: only beside `Node.gps`, each fix valid and from the node's
/// sender, stamps strictly increasing and before `Node.gps`'s.
fn validate_earlier_gps(header: &v1::Header, node: &v1::Node) -> Result<(), WireError> {
    const FIELD: &str = "Node.earlier_gps";
    let Some(latest) = &node.gps else {
        return match node.earlier_gps.len() {
            0 => Ok(()),
            n => Err(WireError::Invalid {
                field: FIELD,
                detail: format!("{n} fixes without Node.gps"),
            }),
        };
    };
    let stamp = |fix: &v1::GpsFix| fix.header.as_ref().map_or(0, |h| h.stamp_ns);
    let mut previous: Option<u64> = None;
    for (k, fix) in node.earlier_gps.iter().enumerate() {
        validate_gps_fix(fix)?;
        if let Some(g) = &fix.header {
            same_sender(header, g, "Node.earlier_gps.header")?;
        }
        let t = stamp(fix);
        if previous.is_some_and(|p| t <= p) || t >= stamp(latest) {
            return Err(WireError::InvalidValue {
                field: FIELD,
                index: Some(k),
                value: t as f64,
                problem: "a stamp not after the fix before it and before Node.gps's",
            });
        }
        previous = Some(t);
    }
    Ok(())
}

/// Checks an ack: header present, of this version, with valid ids.
pub fn validate_ack(ack: &v1::Ack) -> Result<(), WireError> {
    check_header(ack.header.as_ref(), "Ack.header").map(drop)
}

/// Decodes and checks a node ([`validate_node`]): garbage bytes, a missing header, a wire
/// version other than 1 and a bad scan, pose or fix are errors.
pub fn decode_node(bytes: &[u8]) -> Result<v1::Node, WireError> {
    let node: v1::Node = decode("Node", bytes)?;
    validate_node(&node)?;
    Ok(node)
}

/// Decodes and checks live odometry ([`odometry_from_wire`]).
pub fn decode_odometry(bytes: &[u8]) -> Result<v1::Odometry, WireError> {
    let odometry: v1::Odometry = decode("Odometry", bytes)?;
    odometry_from_wire(&odometry)?;
    Ok(odometry)
}

/// Decodes and checks an ack ([`validate_ack`]).
pub fn decode_ack(bytes: &[u8]) -> Result<v1::Ack, WireError> {
    let ack: v1::Ack = decode("Ack", bytes)?;
    validate_ack(&ack)?;
    Ok(ack)
}

#[cfg(test)]
mod tests {
    use super::*;
    use leveling::nalgebra::Vector3;

    const STAMP_NS: u64 = 1_700_000_000_123_456_789;

    fn header(seq: u64) -> v1::Header {
        v1::Header::new("campus", "rover-1", seq, 0, STAMP_NS + 50_000_000)
    }

    fn scan() -> LeveledScan {
        let beams = (0..360)
            .map(|i| Beam {
                bearing_rad: (i as f32).to_radians() - std::f32::consts::PI,
                range_m: (i % 7 != 0).then_some(1.5 + i as f32 * 0.1),
            })
            .collect();
        LeveledScan {
            stamp_ns: STAMP_NS,
            beams,
        }
    }

    fn counts() -> ClassCounts {
        ClassCounts {
            invalid: 100,
            ground: 20_000,
            landmark: 5_000,
            overhang: 1_900,
        }
    }

    fn robot_pose() -> Isometry3<f64> {
        Isometry3::new(
            Vector3::new(12.5, -3.25, 0.75),
            Vector3::new(0.05, -0.02, 1.2),
        )
    }

    fn node() -> v1::Node {
        let mut gps_header = header(4);
        gps_header.stamp_ns = STAMP_NS - 20_000_000;
        v1::Node {
            header: Some(v1::Header::new(
                "campus",
                "rover-1",
                9,
                STAMP_NS,
                STAMP_NS + 1,
            )),
            node_seq: 7,
            scan: Some(leveled_scan_to_wire(&scan(), &counts(), header(9))),
            odometry: Some(odometry_to_wire(
                &TimedPose {
                    stamp_ns: STAMP_NS,
                    pose: robot_pose(),
                },
                header(9),
            )),
            gps: Some(v1::GpsFix {
                header: Some(gps_header.clone()),
                latitude_deg: 52.3822,
                longitude_deg: 9.7166,
                altitude_m: 60.0,
                position_covariance_m2: vec![0.04, 0.0, 0.0, 0.0, 0.04, 0.0, 0.0, 0.0, 0.25],
                status: v1::FixStatus::RtkFixed.into(),
                satellites: 14,
                antenna_offset_m: Some(v1::Vec3 {
                    x: 0.1,
                    y: 0.0,
                    z: 0.9,
                }),
            }),
            earlier_gps: vec![v1::GpsFix {
                header: Some(v1::Header {
                    stamp_ns: STAMP_NS - 1_020_000_000,
                    ..gps_header
                }),
                latitude_deg: 52.38219,
                longitude_deg: 9.71659,
                altitude_m: 60.1,
                position_covariance_m2: vec![0.04, 0.0, 0.0, 0.0, 0.04, 0.0, 0.0, 0.0, 0.25],
                status: v1::FixStatus::RtkFixed.into(),
                satellites: 13,
                antenna_offset_m: Some(v1::Vec3 {
                    x: -1.1,
                    y: 0.05,
                    z: 0.9,
                }),
            }],
            odometry_delta_from_previous: Some(v1::Pose2D {
                x_m: 4.9,
                y_m: 0.2,
                yaw_rad: 0.05,
            }),
            scan_origin_in_robot: Some(v1::Pose2D {
                x_m: 0.3,
                y_m: 0.0,
                yaw_rad: 0.0,
            }),
            cloud: Some(cloud_to_wire(&cloud())),
        }
    }

    /// Four points of three classes, reduced from the valid points of `counts()`.
    fn cloud() -> ClassifiedCloud {
        ClassifiedCloud {
            points_m: vec![
                [1.25, -0.5, -0.75],
                [-12.5, 3.0, 0.25],
                [4.0, 4.0, 2.5],
                [999.99, -999.99, 0.0],
            ],
            classes: vec![
                PointClass::Ground,
                PointClass::Landmark,
                PointClass::Overhang,
                PointClass::Ground,
            ],
            source_points: 26_900,
            voxel_m: 0.1,
            max_points: 6000,
        }
    }

    fn wire_cloud(n: &mut v1::Node) -> &mut v1::SegmentedCloud {
        n.cloud.as_mut().unwrap()
    }

    /// Encodes a node after `edit`, decodes it, and returns the error.
    fn rejection(edit: impl FnOnce(&mut v1::Node)) -> WireError {
        let mut n = node();
        edit(&mut n);
        decode_node(&n.encode_to_vec()).expect_err("must be rejected")
    }

    fn wire_scan(n: &mut v1::Node) -> &mut v1::LeveledScan {
        n.scan.as_mut().unwrap()
    }

    #[test]
    fn leveled_scan_round_trips_through_bytes() {
        let original = scan();
        let bytes = node().encode_to_vec();
        let decoded = decode_node(&bytes).unwrap();
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
    fn poses_round_trip() {
        let pose = robot_pose();
        let back = pose3d_from_wire(&pose3d_to_wire(&pose)).unwrap();
        assert!((back.to_homogeneous() - pose.to_homogeneous()).abs().max() < 1e-12);

        let odometry = odometry_from_wire(
            &decode_odometry(
                &odometry_to_wire(&TimedPose { stamp_ns: 42, pose }, header(1)).encode_to_vec(),
            )
            .unwrap(),
        )
        .unwrap();
        assert_eq!(odometry.stamp_ns, 42);
        assert!(
            (odometry.pose.to_homogeneous() - pose.to_homogeneous())
                .abs()
                .max()
                < 1e-12
        );

        let planar = pose2d_to_wire(&pose);
        assert_eq!((planar.x_m, planar.y_m), (12.5, -3.25));
        assert!((planar.yaw_rad - heading_rad(&pose.rotation)).abs() < 1e-15);
        let p2 = pose2d_from_wire(&planar).unwrap();
        assert!((p2.rotation.angle() - planar.yaw_rad).abs() < 1e-12);
    }

    #[test]
    fn garbage_bytes_are_rejected() {
        for bytes in [&b"garbage"[..], &[0xff; 16], &[0x0a, 0x05, 0x01]] {
            let err = decode_node(bytes).unwrap_err();
            assert!(
                matches!(
                    err,
                    WireError::Decode {
                        message: "Node",
                        ..
                    }
                ),
                "{err}"
            );
            assert!(decode_odometry(bytes).is_err());
            assert!(decode_ack(bytes).is_err());
        }
        // Empty bytes are a valid encoding of an empty node, which has no header.
        assert_eq!(
            decode_node(&[]).unwrap_err(),
            WireError::Missing {
                field: "Node.header"
            }
        );
    }

    #[test]
    fn other_wire_versions_are_rejected() {
        let err = rejection(|n| n.header.as_mut().unwrap().version = 2);
        assert_eq!(
            err,
            WireError::Version {
                field: "Node.header",
                found: 2
            }
        );
        assert!(err.to_string().contains("wire version 2"), "{err}");
        let err = rejection(|n| wire_scan(n).header.as_mut().unwrap().version = 2);
        assert!(matches!(
            err,
            WireError::Version {
                field: "LeveledScan.header",
                found: 2
            }
        ));
        let err = rejection(|n| n.gps.as_mut().unwrap().header.as_mut().unwrap().version = 0);
        assert!(matches!(
            err,
            WireError::Version {
                field: "GpsFix.header",
                found: 0
            }
        ));
        let mut ack = v1::Ack {
            header: Some(header(3)),
            acked_node_seq: 6,
        };
        assert_eq!(decode_ack(&ack.encode_to_vec()).unwrap().acked_node_seq, 6);
        ack.header.as_mut().unwrap().version = 2;
        assert!(decode_ack(&ack.encode_to_vec()).is_err());
    }

    #[test]
    fn missing_parts_are_rejected() {
        assert_eq!(
            rejection(|n| n.header = None),
            WireError::Missing {
                field: "Node.header"
            }
        );
        assert_eq!(
            rejection(|n| n.scan = None),
            WireError::Missing { field: "Node.scan" }
        );
        assert_eq!(
            rejection(|n| wire_scan(n).header = None),
            WireError::Missing {
                field: "LeveledScan.header"
            }
        );
        assert_eq!(
            rejection(|n| n.odometry.as_mut().unwrap().pose = None),
            WireError::Missing {
                field: "Odometry.pose"
            }
        );
        // An unset orientation (all zeros) is not the identity.
        let err = rejection(|n| {
            let p = n.odometry.as_mut().unwrap().pose.as_mut().unwrap();
            (p.qw, p.qx, p.qy, p.qz) = (0.0, 0.0, 0.0, 0.0);
        });
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "Pose3D.qw",
                ..
            }
        ));
        // GPS is optional.
        let mut n = node();
        n.gps = None;
        n.earlier_gps.clear();
        n.odometry_delta_from_previous = None;
        decode_node(&n.encode_to_vec()).unwrap();
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
    fn bad_headers_fixes_and_poses_are_rejected() {
        let err = rejection(|n| n.header.as_mut().unwrap().robot_id = "rover/*".into());
        assert!(matches!(err, WireError::InvalidId { kind: "robot", .. }));
        let err = rejection(|n| wire_scan(n).header.as_mut().unwrap().robot_id = "rover-2".into());
        assert!(matches!(
            err,
            WireError::Invalid {
                field: "Node.scan.header",
                ..
            }
        ));
        let err = rejection(|n| n.gps.as_mut().unwrap().latitude_deg = 91.0);
        assert_eq!(err.to_string(), "GpsFix.latitude_deg = 91 is out of range");
        let err = rejection(|n| n.gps.as_mut().unwrap().position_covariance_m2.truncate(4));
        assert!(matches!(
            err,
            WireError::Invalid {
                field: "GpsFix.position_covariance_m2",
                ..
            }
        ));
        let err = rejection(|n| n.gps.as_mut().unwrap().position_covariance_m2[4] = -0.1);
        assert!(matches!(
            err,
            WireError::InvalidValue {
                index: Some(4),
                problem: "a negative variance",
                ..
            }
        ));
        let err = rejection(|n| n.gps.as_mut().unwrap().status = 42);
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "GpsFix.status",
                ..
            }
        ));
        let err = rejection(|n| n.odometry.as_mut().unwrap().pose.as_mut().unwrap().x_m = f64::NAN);
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "Pose3D.x_m",
                ..
            }
        ));
        let err = rejection(|n| n.odometry.as_mut().unwrap().pose_covariance = vec![0.0; 35]);
        assert!(matches!(
            err,
            WireError::Invalid {
                field: "Odometry.pose_covariance",
                ..
            }
        ));
        let err = rejection(|n| {
            n.odometry_delta_from_previous.as_mut().unwrap().yaw_rad = f64::INFINITY;
        });
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "Pose2D.yaw_rad",
                ..
            }
        ));
    }

    #[test]
    fn bad_earlier_fixes_are_rejected() {
        let err = rejection(|n| n.earlier_gps[0].longitude_deg = f64::NAN);
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "GpsFix.longitude_deg",
                problem: "not finite",
                ..
            }
        ));
        let err = rejection(|n| {
            n.earlier_gps[0].header.as_mut().unwrap().robot_id = "rover-2".into();
        });
        assert!(matches!(
            err,
            WireError::Invalid {
                field: "Node.earlier_gps.header",
                ..
            }
        ));
        // Not before Node.gps, or out of order.
        let err = rejection(|n| {
            let latest = n.gps.as_ref().unwrap().header.as_ref().unwrap().stamp_ns;
            n.earlier_gps[0].header.as_mut().unwrap().stamp_ns = latest;
        });
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "Node.earlier_gps",
                index: Some(0),
                ..
            }
        ));
        let err = rejection(|n| {
            let mut older = n.earlier_gps[0].clone();
            older.header.as_mut().unwrap().stamp_ns -= 1_000_000_000;
            n.earlier_gps.push(older);
        });
        assert!(matches!(
            err,
            WireError::InvalidValue {
                field: "Node.earlier_gps",
                index: Some(1),
                ..
            }
        ));
        let err = rejection(|n| n.gps = None);
        assert!(
            err.to_string().contains("1 fixes without Node.gps"),
            "{err}"
        );
    }

    #[test]
    fn cloud_round_trips_to_the_centimetre() {
        let decoded = decode_node(&node().encode_to_vec()).unwrap();
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
        assert_eq!(decode_node(&n.encode_to_vec()).unwrap(), n);
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
        decode_node(&n.encode_to_vec()).unwrap();
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
        decode_node(&n.encode_to_vec()).unwrap();
        wire_cloud(&mut n).source_points = 3;
        let err = decode_node(&n.encode_to_vec()).unwrap_err();
        assert!(matches!(
            err,
            WireError::Invalid {
                field: "SegmentedCloud.source_points",
                ..
            }
        ));
    }
}
