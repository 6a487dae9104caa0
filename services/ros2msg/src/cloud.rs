//! A `PointCloud2`'s points: x, y, z (and a ring and a time per point where the driver
//! gives them) read at their offsets, in their types and byte order, with every layout
//! checked first, so that no cloud, however malformed, reads outside its data.

use crate::{PointCloud2, PointField};

/// The fields levelmap uses, one entry per point (row after row).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CloudPoints {
    /// Position in the cloud's frame (m); NaN for a point with no return.
    pub xyz: Vec<[f32; 3]>,
    /// The laser (`ring`, or `channel`), when the cloud has one.
    pub ring: Option<Vec<u16>>,
    /// Time after the header's stamp (ns; negative when the stamp is the scan's end), when
    /// the cloud has a per-point time (`t`, `time`, `timestamp`, `time_stamp`).
    pub offset_ns: Option<Vec<i64>>,
}

/// Why a cloud's points cannot be read.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CloudError {
    /// No field of that name.
    #[error("the cloud has no `{0}` field")]
    MissingField(&'static str),
    /// A field of a type that cannot be that quantity.
    #[error("field `{name}` has datatype {datatype}, not a number this field can be")]
    FieldType {
        /// The field.
        name: String,
        /// Its `datatype`.
        datatype: u8,
    },
    /// Sizes that do not fit together (a field beyond its point, rows beyond the data…).
    #[error("bad layout: {0}")]
    Layout(String),
}

/// Bytes of a `PointField` datatype; `None` for an unknown one.
fn datatype_size(datatype: u8) -> Option<usize> {
    match datatype {
        1 | 2 => Some(1),
        3 | 4 => Some(2),
        5..=7 => Some(4),
        8 => Some(8),
        _ => None,
    }
}

/// Reads a value at the start of a slice as f64.
type Reader = fn(&[u8]) -> f64;

/// The reader of a `PointField` datatype (known: [`datatype_size`] is `Some`).
fn reader(datatype: u8, big: bool) -> Reader {
    macro_rules! num {
        ($t:ty, $n:expr) => {
            if big {
                |b: &[u8]| <$t>::from_be_bytes(b[..$n].try_into().expect("sized")) as f64
            } else {
                |b: &[u8]| <$t>::from_le_bytes(b[..$n].try_into().expect("sized")) as f64
            }
        };
    }
    match datatype {
        1 => |b: &[u8]| b[0] as i8 as f64,
        2 => |b: &[u8]| b[0] as f64,
        3 => num!(i16, 2),
        4 => num!(u16, 2),
        5 => num!(i32, 4),
        6 => num!(u32, 4),
        7 => num!(f32, 4),
        _ => num!(f64, 8),
    }
}

/// A field's offset in the point, its datatype, and its reader.
type Field = (usize, u8, Reader);

/// A field of the cloud checked against the point's size: (offset, datatype).
fn field(
    cloud: &PointCloud2<'_>,
    names: &[&'static str],
    floats_only: bool,
) -> Result<Option<Field>, CloudError> {
    let Some(f): Option<&PointField> = cloud
        .fields
        .iter()
        .find(|f| names.contains(&f.name.as_str()))
    else {
        return Ok(None);
    };
    let bad_type = || CloudError::FieldType {
        name: f.name.clone(),
        datatype: f.datatype,
    };
    let size = datatype_size(f.datatype).ok_or_else(bad_type)?;
    if floats_only && f.datatype < 7 {
        return Err(bad_type());
    }
    let offset = f.offset as usize;
    if offset + size > cloud.point_step as usize {
        return Err(CloudError::Layout(format!(
            "field `{}` ends at byte {} of a {}-byte point",
            f.name,
            offset + size,
            cloud.point_step
        )));
    }
    Ok(Some((
        offset,
        f.datatype,
        reader(f.datatype, cloud.is_bigendian),
    )))
}

impl CloudPoints {
    /// The points of `cloud`; an error for a cloud without x, y, z or whose sizes do not fit.
    pub fn from_cloud(cloud: &PointCloud2<'_>) -> Result<CloudPoints, CloudError> {
        let required = |names: &[&'static str]| {
            field(cloud, names, true)?.ok_or(CloudError::MissingField(names[0]))
        };
        let (x, y, z) = (required(&["x"])?, required(&["y"])?, required(&["z"])?);
        let ring = field(cloud, &["ring", "channel"], false)?;
        let time = field(cloud, &["t", "time", "timestamp", "time_stamp"], false)?;
        let (width, height) = (cloud.width as usize, cloud.height as usize);
        let (step, row_step) = (cloud.point_step as usize, cloud.row_step as usize);
        if width * step > row_step && height > 0 {
            return Err(CloudError::Layout(format!(
                "{width} points of {step} bytes do not fit a {row_step}-byte row"
            )));
        }
        let needed = if height == 0 {
            0
        } else {
            (height - 1) * row_step + width * step
        };
        if cloud.data.len() < needed {
            return Err(CloudError::Layout(format!(
                "{height} rows need {needed} bytes, the data has {}",
                cloud.data.len()
            )));
        }
        let stamp_ns = cloud.header.stamp.to_ns().unwrap_or(0) as i64;
        let mut points = CloudPoints {
            xyz: Vec::with_capacity(width * height),
            ring: ring.map(|_| Vec::with_capacity(width * height)),
            offset_ns: time.map(|_| Vec::with_capacity(width * height)),
        };
        for row in 0..height {
            let bytes = &cloud.data[row * row_step..row * row_step + width * step];
            for p in bytes.chunks_exact(step) {
                let get = |(offset, _, read): Field| read(&p[offset..]);
                points
                    .xyz
                    .push([get(x) as f32, get(y) as f32, get(z) as f32]);
                if let (Some(out), Some(f)) = (points.ring.as_mut(), ring) {
                    out.push(get(f).clamp(0.0, u16::MAX as f64) as u16);
                }
                if let (Some(out), Some(f)) = (points.offset_ns.as_mut(), time) {
                    out.push(offset_ns(get(f), f.1, stamp_ns));
                }
            }
        }
        Ok(points)
    }
}

/// A point's time as ns after the stamp. Drivers differ: integers are ns (Ouster's `t`),
/// floats are seconds (Velodyne's `time`, Hesai's `timestamp`); a value past 1e9 s (2001)
/// is absolute, else relative to the stamp.
fn offset_ns(value: f64, datatype: u8, stamp_ns: i64) -> i64 {
    let ns = if datatype >= 7 { value * 1e9 } else { value };
    if ns > 1e18 {
        ns as i64 - stamp_ns
    } else {
        ns as i64
    }
}
