//! The ROS 2 messages levelmap reads from a robot (`sensor_msgs/PointCloud2`, `Imu`,
//! `NavSatFix`, `nav_msgs/Odometry`, `tf2_msgs/TFMessage`) and writes back (`TFMessage`,
//! `nav_msgs/OccupancyGrid`), as ROS 2 puts them on the wire: CDR (XCDR1) with the 4-byte
//! encapsulation header, little or big endian. The message structs are plain serde types
//! and `cdr-encoding` (the CDR crate of the Rust ROS 2 client, ros2-client) does the
//! encoding; the one exception is a point cloud's data, megabytes that serde would take
//! byte by byte: [`decode_cloud`] decodes the cloud's head with serde and borrows the data.
//! [`cloud`] turns a cloud's fields into points, whatever their offsets and types.
//! No I/O: the edge service's sources bring the bytes (Zenoh, MCAP).

pub mod cloud;
pub mod msg;
pub mod types;

pub use cloud::{CloudError, CloudPoints};
pub use msg::*;
pub use types::RosType;

use byteorder::{BigEndian, ByteOrder, LittleEndian};
use serde::{Serialize, de::DeserializeOwned};

/// Why a sample is not the message it should be.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum DecodeError {
    /// Shorter than the 4-byte encapsulation header.
    #[error("{0} bytes: no CDR encapsulation header")]
    NoHeader(usize),
    /// Not plain CDR (XCDR1) in either byte order: e.g. XCDR2 or parameter lists.
    #[error("encapsulation {0:#06x} is not CDR_LE (0x0001) or CDR_BE (0x0000)")]
    Encapsulation(u16),
    /// The bytes do not hold the message (too short, a bad length, a bad string…).
    #[error("{0}")]
    Cdr(String),
}

/// Plain CDR in little (`true`) or big endian, from the encapsulation header.
fn little_endian(sample: &[u8]) -> Result<bool, DecodeError> {
    let kind = match sample {
        [a, b, _, _, ..] => u16::from_be_bytes([*a, *b]),
        _ => return Err(DecodeError::NoHeader(sample.len())),
    };
    match kind {
        0x0001 => Ok(true),
        0x0000 => Ok(false),
        other => Err(DecodeError::Encapsulation(other)),
    }
}

/// The message in `sample` (encapsulation header, then CDR). Bytes after the message
/// (alignment padding) are ignored.
pub fn decode<T: DeserializeOwned>(sample: &[u8]) -> Result<T, DecodeError> {
    decode_prefix(sample).map(|(message, _)| message)
}

/// The message and how many bytes of the payload (after the header) it took.
fn decode_prefix<T: DeserializeOwned>(sample: &[u8]) -> Result<(T, usize), DecodeError> {
    let payload = &sample[4.min(sample.len())..];
    let decoded = if little_endian(sample)? {
        cdr_encoding::from_bytes::<T, LittleEndian>(payload)
    } else {
        cdr_encoding::from_bytes::<T, BigEndian>(payload)
    };
    decoded.map_err(|e| DecodeError::Cdr(e.to_string()))
}

/// `message` as a sample: little-endian CDR after its encapsulation header.
pub fn encode<T: Serialize>(message: &T) -> Vec<u8> {
    let mut sample = vec![0x00, 0x01, 0x00, 0x00];
    cdr_encoding::to_writer::<T, LittleEndian, _>(&mut sample, message)
        .expect("the message types serialize to a Vec");
    sample
}

/// `sensor_msgs/msg/PointCloud2`, its data borrowed from the sample.
#[derive(Clone, Debug, PartialEq)]
pub struct PointCloud2<'a> {
    /// Stamp (by convention the scan's start or end: see the driver) and the lidar's frame.
    pub header: Header,
    /// Rows (1 for an unorganized cloud).
    pub height: u32,
    /// Points per row.
    pub width: u32,
    /// The fields of a point.
    pub fields: Vec<PointField>,
    /// The data's byte order.
    pub is_bigendian: bool,
    /// Bytes per point.
    pub point_step: u32,
    /// Bytes per row.
    pub row_step: u32,
    /// `height` rows of `row_step` bytes.
    pub data: &'a [u8],
    /// No invalid (NaN) points.
    pub is_dense: bool,
}

/// The cloud in `sample`, its data borrowed.
pub fn decode_cloud(sample: &[u8]) -> Result<PointCloud2<'_>, DecodeError> {
    let (head, used): (msg::CloudHead, usize) = decode_prefix(sample)?;
    let payload = &sample[4..];
    let short = || DecodeError::Cdr("the cloud's data is cut short".into());
    // The data's length is a u32 aligned to 4 from the payload's start.
    let at = used.next_multiple_of(4);
    let len_bytes = payload.get(at..at + 4).ok_or_else(short)?;
    let len = if little_endian(sample)? {
        LittleEndian::read_u32(len_bytes)
    } else {
        BigEndian::read_u32(len_bytes)
    } as usize;
    let start = at + 4;
    let data = payload.get(start..start + len).ok_or_else(short)?;
    let is_dense = match payload.get(start + len) {
        Some(0) => false,
        Some(1) => true,
        Some(other) => return Err(DecodeError::Cdr(format!("is_dense is {other}"))),
        None => return Err(short()),
    };
    Ok(PointCloud2 {
        header: head.header,
        height: head.height,
        width: head.width,
        fields: head.fields,
        is_bigendian: head.is_bigendian,
        point_step: head.point_step,
        row_step: head.row_step,
        data,
        is_dense,
    })
}

/// A cloud as a sample (for tests and recordings): little-endian CDR.
pub fn encode_cloud(cloud: &PointCloud2<'_>) -> Vec<u8> {
    let head = msg::CloudHead {
        header: cloud.header.clone(),
        height: cloud.height,
        width: cloud.width,
        fields: cloud.fields.clone(),
        is_bigendian: cloud.is_bigendian,
        point_step: cloud.point_step,
        row_step: cloud.row_step,
    };
    let mut sample = encode(&head);
    while !(sample.len() - 4).is_multiple_of(4) {
        sample.push(0);
    }
    sample.extend_from_slice(&(cloud.data.len() as u32).to_le_bytes());
    sample.extend_from_slice(cloud.data);
    sample.push(u8::from(cloud.is_dense));
    sample
}

#[cfg(test)]
mod tests;
