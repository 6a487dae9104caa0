//! The Ouster sensor metadata JSON: packet layout and beam intrinsics.
//!
//! Two layouts exist. The legacy flat one (FW 2.x, the shared files): beam angles, the beam
//! origin and `lidar_to_sensor_transform` at the top level, packet layout in `data_format`.
//! The nested one (FW 3.x, SDK ≥ 0.10): `beam_intrinsics`, `lidar_intrinsics`,
//! `lidar_data_format`, `config_params`. Each field is looked up in both places.

use crate::LoadError;
use serde_json::Value;
use std::path::Path;

/// A lidar packet layout (`udp_profile_lidar`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Profile {
    /// FW < 2.2: per-column headers and status, 12 bytes per pixel.
    Legacy,
    /// Single return, 19-bit range in mm, 12 bytes per pixel.
    Rng19Rfl8Sig16Nir16,
    /// Low bandwidth: 15-bit range in units of 8 mm, 4 bytes per pixel.
    Rng15Rfl8Nir8,
}

impl Profile {
    fn parse(name: &str) -> Option<Profile> {
        match name {
            "LEGACY" => Some(Profile::Legacy),
            "RNG19_RFL8_SIG16_NIR16" => Some(Profile::Rng19Rfl8Sig16Nir16),
            "RNG15_RFL8_NIR8" => Some(Profile::Rng15Rfl8Nir8),
            _ => None,
        }
    }
}

/// What scanio needs of a sensor's metadata, checked for consistency.
#[derive(Clone, Debug, PartialEq)]
pub struct SensorMeta {
    /// Product line, e.g. "OS-1-128" (for reports).
    pub prod_line: String,
    /// UDP port of the lidar packets (default 7502).
    pub udp_port_lidar: u16,
    /// The lidar packet layout.
    pub profile: Profile,
    /// Measurement columns per rotation (512, 1024, 2048).
    pub columns_per_frame: usize,
    /// Columns in one lidar packet.
    pub columns_per_packet: usize,
    /// Beams (rows), top-down as the packets order them.
    pub pixels_per_column: usize,
    /// Per row: the shift that destaggers it (columns).
    pub pixel_shift_by_row: Vec<i64>,
    /// First and last measurement id the sensor sends (inclusive).
    pub column_window: (usize, usize),
    /// Per row: elevation (deg), top-down.
    pub beam_altitude_deg: Vec<f64>,
    /// Per row: azimuth offset (deg).
    pub beam_azimuth_deg: Vec<f64>,
    /// The beam origin in the lidar frame (mm): x (the classic lidar_origin_to_beam_origin_mm)
    /// and z (0 on OS sensors).
    pub beam_origin_mm: (f64, f64),
    /// Lidar frame → sensor frame, row-major 4 × 4 (translation in mm).
    pub lidar_to_sensor: [f64; 16],
}

impl SensorMeta {
    /// Reads and checks a metadata file.
    pub fn load(path: &Path) -> Result<SensorMeta, LoadError> {
        SensorMeta::parse(&crate::read_nonempty(path)?, path)
    }

    /// Parses and checks metadata JSON (`path` names it in errors).
    pub fn parse(bytes: &[u8], path: &Path) -> Result<SensorMeta, LoadError> {
        let root: Value = serde_json::from_slice(bytes)
            .map_err(|e| LoadError::invalid(path, format!("not JSON: {e}")))?;
        let get = |nested: &str, flat: &str| lookup(&root, nested).or_else(|| lookup(&root, flat));
        let missing = |name: &str| LoadError::invalid(path, format!("metadata lacks {name}"));
        let number = |nested: &str, flat: &str| -> Result<f64, LoadError> {
            get(nested, flat)
                .and_then(Value::as_f64)
                .ok_or_else(|| missing(flat))
        };
        let count = |nested: &str, flat: &str| -> Result<usize, LoadError> {
            get(nested, flat)
                .and_then(Value::as_u64)
                .map(|v| v as usize)
                .ok_or_else(|| missing(flat))
        };
        let numbers = |nested: &str, flat: &str| -> Result<Vec<f64>, LoadError> {
            get(nested, flat)
                .and_then(Value::as_array)
                .and_then(|a| a.iter().map(Value::as_f64).collect::<Option<Vec<f64>>>())
                .ok_or_else(|| missing(&format!("{flat} (an array of numbers)")))
        };

        let beam_altitude_deg = numbers(
            "beam_intrinsics.beam_altitude_angles",
            "beam_altitude_angles",
        )?;
        let beam_azimuth_deg =
            numbers("beam_intrinsics.beam_azimuth_angles", "beam_azimuth_angles")?;
        let origin_x = number(
            "beam_intrinsics.lidar_origin_to_beam_origin_mm",
            "lidar_origin_to_beam_origin_mm",
        )?;
        // The SDK uses beam_to_lidar_transform when present (its z, usually 0), else x alone.
        let beam_to_lidar = numbers(
            "beam_intrinsics.beam_to_lidar_transform",
            "beam_to_lidar_transform",
        )
        .ok()
        .filter(|m| m.len() == 16);
        let beam_origin_mm = beam_to_lidar.map_or((origin_x, 0.0), |m| (m[3], m[11]));
        let transform = numbers(
            "lidar_intrinsics.lidar_to_sensor_transform",
            "lidar_to_sensor_transform",
        )?;
        let lidar_to_sensor: [f64; 16] = transform.as_slice().try_into().map_err(|_| {
            LoadError::invalid(
                path,
                format!(
                    "lidar_to_sensor_transform has {} numbers, not 16",
                    transform.len()
                ),
            )
        })?;
        let profile_name = get(
            "lidar_data_format.udp_profile_lidar",
            "data_format.udp_profile_lidar",
        )
        .or_else(|| lookup(&root, "config_params.udp_profile_lidar"))
        .and_then(Value::as_str)
        .unwrap_or("LEGACY");
        let profile = Profile::parse(profile_name).ok_or_else(|| {
            LoadError::invalid(
                path,
                format!(
                    "udp_profile_lidar {profile_name:?} is not read \
                     (LEGACY, RNG19_RFL8_SIG16_NIR16, RNG15_RFL8_NIR8)"
                ),
            )
        })?;
        let columns_per_frame = count(
            "lidar_data_format.columns_per_frame",
            "data_format.columns_per_frame",
        )?;
        let columns_per_packet = count(
            "lidar_data_format.columns_per_packet",
            "data_format.columns_per_packet",
        )?;
        let pixels_per_column = count(
            "lidar_data_format.pixels_per_column",
            "data_format.pixels_per_column",
        )?;
        let pixel_shift_by_row = numbers(
            "lidar_data_format.pixel_shift_by_row",
            "data_format.pixel_shift_by_row",
        )?
        .iter()
        .map(|&v| v as i64)
        .collect::<Vec<_>>();
        let window = numbers(
            "lidar_data_format.column_window",
            "data_format.column_window",
        )
        .unwrap_or_else(|_| vec![0.0, columns_per_frame.saturating_sub(1) as f64]);
        let udp_port_lidar = get("config_params.udp_port_lidar", "udp_port_lidar")
            .and_then(Value::as_u64)
            .unwrap_or(7502) as u16;
        let prod_line = get("sensor_info.prod_line", "prod_line")
            .and_then(Value::as_str)
            .unwrap_or("Ouster")
            .to_owned();

        let rows = pixels_per_column;
        let bad = |message: String| Err(LoadError::invalid(path, message));
        for (name, len) in [
            ("beam_altitude_angles", beam_altitude_deg.len()),
            ("beam_azimuth_angles", beam_azimuth_deg.len()),
            ("pixel_shift_by_row", pixel_shift_by_row.len()),
        ] {
            if len != rows {
                return bad(format!(
                    "{name} has {len} entries for {rows} pixels per column"
                ));
            }
        }
        if !(1..=256).contains(&rows)
            || !(1..=64).contains(&columns_per_packet)
            || !(16..=8192).contains(&columns_per_frame)
        {
            return bad(format!(
                "implausible packet layout: {rows} pixels per column, {columns_per_packet} \
                 columns per packet, {columns_per_frame} per frame"
            ));
        }
        let column_window = match window.as_slice() {
            &[a, b] if a >= 0.0 && a <= b && (b as usize) < columns_per_frame => {
                (a as usize, b as usize)
            }
            other => return bad(format!("column_window {other:?} is not within the frame")),
        };
        let finite = beam_altitude_deg
            .iter()
            .chain(&beam_azimuth_deg)
            .chain(&lidar_to_sensor)
            .all(|v| v.is_finite());
        if !finite || !origin_x.is_finite() || !beam_origin_mm.1.is_finite() {
            return bad("a beam angle or transform is not finite".into());
        }
        Ok(SensorMeta {
            prod_line,
            udp_port_lidar,
            profile,
            columns_per_frame,
            columns_per_packet,
            pixels_per_column,
            pixel_shift_by_row,
            column_window,
            beam_altitude_deg,
            beam_azimuth_deg,
            beam_origin_mm,
            lidar_to_sensor,
        })
    }
}

/// `a.b.c` in nested objects.
fn lookup<'a>(root: &'a Value, dotted: &str) -> Option<&'a Value> {
    dotted.split('.').try_fold(root, |v, key| v.get(key))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat() -> Value {
        serde_json::json!({
            "beam_altitude_angles": [1.0, -1.0],
            "beam_azimuth_angles": [0.5, -0.5],
            "lidar_origin_to_beam_origin_mm": 12.0,
            "lidar_to_sensor_transform": [-1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 36.0, 0, 0, 0, 1],
            "data_format": {
                "columns_per_frame": 512, "columns_per_packet": 16, "pixels_per_column": 2,
                "pixel_shift_by_row": [4, 0], "column_window": [0, 511],
                "udp_profile_lidar": "RNG19_RFL8_SIG16_NIR16"
            },
            "udp_port_lidar": 7502,
            "prod_line": "OS-1-16"
        })
    }

    fn parse(v: &Value) -> Result<SensorMeta, LoadError> {
        SensorMeta::parse(v.to_string().as_bytes(), Path::new("m.json"))
    }

    #[test]
    fn flat_and_nested_layouts_read_the_same() {
        let a = parse(&flat()).unwrap();
        let f = flat();
        let nested = serde_json::json!({
            "beam_intrinsics": {
                "beam_altitude_angles": f["beam_altitude_angles"],
                "beam_azimuth_angles": f["beam_azimuth_angles"],
                "lidar_origin_to_beam_origin_mm": 12.0,
                "beam_to_lidar_transform": [1, 0, 0, 12.0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
            },
            "lidar_intrinsics": {"lidar_to_sensor_transform": f["lidar_to_sensor_transform"]},
            "lidar_data_format": f["data_format"],
            "config_params": {"udp_port_lidar": 7502},
            "sensor_info": {"prod_line": "OS-1-16"}
        });
        assert_eq!(parse(&nested).unwrap(), a);
        assert_eq!(a.profile, Profile::Rng19Rfl8Sig16Nir16);
        assert_eq!(a.column_window, (0, 511));
    }

    #[test]
    fn missing_or_inconsistent_fields_are_errors_naming_the_file() {
        let mut v = flat();
        v.as_object_mut().unwrap().remove("beam_altitude_angles");
        let e = parse(&v).unwrap_err().to_string();
        assert!(
            e.starts_with("m.json: metadata lacks beam_altitude_angles"),
            "{e}"
        );

        let mut v = flat();
        v["data_format"]["pixel_shift_by_row"] = serde_json::json!([1]);
        let e = parse(&v).unwrap_err().to_string();
        assert!(e.contains("pixel_shift_by_row has 1 entries"), "{e}");

        let mut v = flat();
        v["data_format"]["udp_profile_lidar"] = "FUSA_RNG15".into();
        assert!(parse(&v).unwrap_err().to_string().contains("FUSA_RNG15"));

        let e = SensorMeta::parse(b"{", Path::new("m.json")).unwrap_err();
        assert!(e.to_string().starts_with("m.json: not JSON"), "{e}");
    }
}
