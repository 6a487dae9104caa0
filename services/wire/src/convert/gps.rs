//! GPS fixes: checked, and to and from the one GPS fix model ([`slam::gnss`]).

use super::check_header;
use super::pose::{check_covariance, check_vec3};
use crate::error::{finite, within};
use crate::{WireError, v1};
use slam::geodesy::Geodetic;
use slam::gnss::{FixStatus, GpsFix};
use slam::nalgebra::{Matrix3, Vector3};

/// Checks a GPS fix: header, WGS84 latitude in [-90, 90] and longitude in [-180, 180]°,
/// finite altitude and lever arm, a known status, a covariance of 9 values or none.
pub fn validate_gps_fix(fix: &v1::GpsFix) -> Result<(), WireError> {
    check_header(fix.header.as_ref(), "GpsFix.header")?;
    within("GpsFix.latitude_deg", fix.latitude_deg, 90.0)?;
    within("GpsFix.longitude_deg", fix.longitude_deg, 180.0)?;
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

/// The fix status on the wire.
pub fn fix_status_to_wire(status: FixStatus) -> v1::FixStatus {
    match status {
        FixStatus::Unspecified => v1::FixStatus::Unspecified,
        FixStatus::NoFix => v1::FixStatus::NoFix,
        FixStatus::Fix => v1::FixStatus::Fix,
        FixStatus::Dgps => v1::FixStatus::Dgps,
        FixStatus::RtkFloat => v1::FixStatus::RtkFloat,
        FixStatus::RtkFixed => v1::FixStatus::RtkFixed,
    }
}

fn fix_status_from_wire(status: v1::FixStatus) -> FixStatus {
    match status {
        v1::FixStatus::Unspecified => FixStatus::Unspecified,
        v1::FixStatus::NoFix => FixStatus::NoFix,
        v1::FixStatus::Fix => FixStatus::Fix,
        v1::FixStatus::Dgps => FixStatus::Dgps,
        v1::FixStatus::RtkFloat => FixStatus::RtkFloat,
        v1::FixStatus::RtkFixed => FixStatus::RtkFixed,
    }
}

/// A fix on the wire, stamped `fix.stamp_ns` in a copy of `header`.
pub fn gps_fix_to_wire(fix: &GpsFix, header: v1::Header) -> v1::GpsFix {
    let a = &fix.antenna_offset_m;
    v1::GpsFix {
        header: Some(v1::Header {
            stamp_ns: fix.stamp_ns,
            ..header
        }),
        latitude_deg: fix.position.latitude_deg,
        longitude_deg: fix.position.longitude_deg,
        altitude_m: fix.position.height_m,
        position_covariance_m2: fix
            .covariance_m2
            .map_or_else(Vec::new, |c| c.transpose().iter().copied().collect()),
        status: fix_status_to_wire(fix.status).into(),
        satellites: 0,
        antenna_offset_m: Some(v1::Vec3 {
            x: a.x,
            y: a.y,
            z: a.z,
        }),
    }
}

/// A fix from the wire, checked ([`validate_gps_fix`]).
pub fn gps_fix_from_wire(fix: &v1::GpsFix) -> Result<GpsFix, WireError> {
    validate_gps_fix(fix)?;
    let stamp_ns = fix.header.as_ref().map_or(0, |h| h.stamp_ns);
    let status = v1::FixStatus::try_from(fix.status).unwrap_or(v1::FixStatus::Unspecified);
    let c = &fix.position_covariance_m2;
    Ok(GpsFix {
        stamp_ns,
        position: Geodetic {
            latitude_deg: fix.latitude_deg,
            longitude_deg: fix.longitude_deg,
            height_m: fix.altitude_m,
        },
        covariance_m2: (c.len() == 9).then(|| Matrix3::from_row_slice(c)),
        status: fix_status_from_wire(status),
        antenna_offset_m: fix
            .antenna_offset_m
            .as_ref()
            .map_or(Vector3::zeros(), |v| Vector3::new(v.x, v.y, v.z)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fix_round_trips_through_the_model() {
        let fix = GpsFix {
            stamp_ns: 42,
            position: Geodetic {
                latitude_deg: 52.3,
                longitude_deg: 9.7,
                height_m: 61.5,
            },
            covariance_m2: Some(Matrix3::new(1.0, 0.1, 0.0, 0.1, 2.0, 0.0, 0.0, 0.0, 4.0)),
            status: FixStatus::RtkFloat,
            antenna_offset_m: Vector3::new(-0.5, 0.1, 1.2),
        };
        let header = v1::Header::new("park", "r0", 0, 0, 0);
        let wire = gps_fix_to_wire(&fix, header);
        assert_eq!(wire.position_covariance_m2[1], 0.1);
        assert_eq!(gps_fix_from_wire(&wire).unwrap(), fix);
        let unknown = GpsFix {
            covariance_m2: None,
            ..fix
        };
        assert_eq!(
            gps_fix_from_wire(&gps_fix_to_wire(
                &unknown,
                v1::Header::new("park", "r0", 0, 0, 0)
            ))
            .unwrap(),
            unknown
        );
    }
}
