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

/// A cloud's fields and sizes, checked: every point of every row lies inside the data, and
/// every field inside its point.
struct Layout {
    x: Field,
    y: Field,
    z: Field,
    ring: Option<Field>,
    time: Option<Field>,
    width: usize,
    height: usize,
    step: usize,
    row_step: usize,
    stamp_ns: i64,
}

impl Layout {
    fn of(cloud: &PointCloud2<'_>) -> Result<Layout, CloudError> {
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
        Ok(Layout {
            x,
            y,
            z,
            ring,
            time,
            width,
            height,
            step,
            row_step,
            stamp_ns: cloud.header.stamp.to_ns().unwrap_or(0) as i64,
        })
    }

    /// Each row's points, `step` bytes each. No rows when a row has no point: a cloud of
    /// 0 × 4 billion rows (its data may be empty) is not 4 billion empty loops.
    fn rows<'a>(&self, data: &'a [u8]) -> impl Iterator<Item = &'a [u8]> + use<'a> {
        let (row_step, row_bytes) = (self.row_step, self.width * self.step);
        let rows = if row_bytes == 0 { 0 } else { self.height };
        (0..rows).map(move |row| &data[row * row_step..row * row_step + row_bytes])
    }

    fn empty_points(&self) -> CloudPoints {
        let n = self.width * self.height;
        CloudPoints {
            xyz: Vec::with_capacity(n),
            ring: self.ring.map(|_| Vec::with_capacity(n)),
            offset_ns: self.time.map(|_| Vec::with_capacity(n)),
        }
    }

    /// The fast loop's layout, when the cloud has one: little endian, x, y, z consecutive
    /// f32 (every lidar driver's layout), a u16 ring or none, a u32, f32 or f64 time or none.
    fn fast(&self, cloud: &PointCloud2<'_>) -> Option<FastLayout> {
        let xyz_at = self.x.0;
        let f32s = [self.x, self.y, self.z].iter().all(|f| f.1 == 7);
        if cloud.is_bigendian || !f32s || self.y.0 != xyz_at + 4 || self.z.0 != xyz_at + 8 {
            return None;
        }
        let ring_at = match self.ring {
            None => None,
            Some((at, 4, _)) => Some(at),
            Some(_) => return None,
        };
        let time = match self.time {
            None => FastTime::None,
            Some((at, 6, _)) => FastTime::U32(at),
            Some((at, 7, _)) => FastTime::F32(at),
            Some((at, 8, _)) => FastTime::F64(at),
            Some(_) => return None,
        };
        Some(FastLayout {
            xyz_at,
            ring_at,
            time,
        })
    }

    /// Any layout: each field read as f64 by its reader.
    fn generic_points(&self, data: &[u8]) -> CloudPoints {
        let mut points = self.empty_points();
        let (x, y, z, ring, time) = (self.x, self.y, self.z, self.ring, self.time);
        for bytes in self.rows(data) {
            for p in bytes.chunks_exact(self.step) {
                let get = |(offset, _, read): Field| read(&p[offset..]);
                points
                    .xyz
                    .push([get(x) as f32, get(y) as f32, get(z) as f32]);
                if let (Some(out), Some(f)) = (points.ring.as_mut(), ring) {
                    out.push(get(f).clamp(0.0, u16::MAX as f64) as u16);
                }
                if let (Some(out), Some(f)) = (points.offset_ns.as_mut(), time) {
                    out.push(offset_ns(get(f), f.1, self.stamp_ns));
                }
            }
        }
        points
    }

    /// The common layouts ([`Layout::fast`]): the same points as [`Layout::generic_points`]
    /// in a fifth of the time (README, "Speed"). No reader or datatype chosen per point:
    /// each row (in cache) is read once per output, by a loop over fixed types whose
    /// `extend` writes into the reserved space without a capacity check per point.
    fn fast_points(&self, data: &[u8], fast: FastLayout) -> CloudPoints {
        let mut points = self.empty_points();
        let stamp_ns = self.stamp_ns;
        for row in self.rows(data) {
            let row = row.chunks_exact(self.step);
            points.xyz.extend(row.clone().map(|p| {
                let xyz: [u8; 12] = le_bytes(p, fast.xyz_at);
                let f = |i: usize| f32::from_le_bytes([xyz[i], xyz[i + 1], xyz[i + 2], xyz[i + 3]]);
                [f(0), f(4), f(8)]
            }));
            if let (Some(out), Some(at)) = (points.ring.as_mut(), fast.ring_at) {
                out.extend(row.clone().map(|p| u16::from_le_bytes(le_bytes(p, at))));
            }
            let Some(out) = points.offset_ns.as_mut() else {
                continue;
            };
            match fast.time {
                FastTime::None => {}
                // Integers are ns and a u32 is never past 1e18: `offset_ns` is the value.
                FastTime::U32(at) => {
                    out.extend(row.map(|p| i64::from(u32::from_le_bytes(le_bytes(p, at)))))
                }
                FastTime::F32(at) => out.extend(row.map(|p| {
                    let t = f32::from_le_bytes(le_bytes(p, at));
                    offset_ns(f64::from(t), 7, stamp_ns)
                })),
                FastTime::F64(at) => out.extend(
                    row.map(|p| offset_ns(f64::from_le_bytes(le_bytes(p, at)), 8, stamp_ns)),
                ),
            }
        }
        points
    }
}

/// Where the fast loop reads a point's fields (byte offsets in the point).
#[derive(Clone, Copy, Debug)]
struct FastLayout {
    xyz_at: usize,
    ring_at: Option<usize>,
    time: FastTime,
}

/// A point's time field in the fast loop: its type and offset.
#[derive(Clone, Copy, Debug)]
enum FastTime {
    None,
    U32(usize),
    F32(usize),
    F64(usize),
}

/// `N` bytes of a point at `at` (checked by [`Layout::of`] to lie inside the point).
fn le_bytes<const N: usize>(point: &[u8], at: usize) -> [u8; N] {
    point[at..at + N].try_into().expect("N bytes")
}

impl CloudPoints {
    /// The points of `cloud`; an error for a cloud without x, y, z or whose sizes do not fit.
    pub fn from_cloud(cloud: &PointCloud2<'_>) -> Result<CloudPoints, CloudError> {
        let layout = Layout::of(cloud)?;
        Ok(match layout.fast(cloud) {
            Some(fast) => layout.fast_points(cloud.data, fast),
            None => layout.generic_points(cloud.data),
        })
    }

    /// The points of `cloud` read field by field whatever its layout (what the fast loop
    /// must match).
    #[cfg(test)]
    pub(crate) fn from_cloud_generic(cloud: &PointCloud2<'_>) -> Result<CloudPoints, CloudError> {
        Ok(Layout::of(cloud)?.generic_points(cloud.data))
    }

    /// Whether `cloud` is read by the fast loop.
    #[cfg(test)]
    pub(crate) fn has_fast_layout(cloud: &PointCloud2<'_>) -> bool {
        Layout::of(cloud).is_ok_and(|layout| layout.fast(cloud).is_some())
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
