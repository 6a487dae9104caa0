//! The messages, field for field as their ROS 2 IDL (order matters: CDR has no names).

use serde::{Deserialize, Serialize};
use serde_big_array::BigArray;

/// `builtin_interfaces/msg/Time`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

impl Time {
    /// Nanoseconds since the epoch; `None` before it.
    pub fn to_ns(self) -> Option<u64> {
        u64::try_from(self.sec)
            .ok()
            .map(|s| s * 1_000_000_000 + u64::from(self.nanosec))
    }

    /// The time of `ns` nanoseconds since the epoch (seconds saturate in 2038, as ROS 2's).
    pub fn from_ns(ns: u64) -> Time {
        Time {
            sec: i32::try_from(ns / 1_000_000_000).unwrap_or(i32::MAX),
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }
}

/// `std_msgs/msg/Header`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// When the data was measured.
    pub stamp: Time,
    /// The frame the data is in.
    pub frame_id: String,
}

/// `geometry_msgs/msg/Vector3` (and `Point`, the same layout).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// `geometry_msgs/msg/Pose`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position (m).
    pub position: Vector3,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/PoseWithCovariance`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose,
    /// Row-major 6×6 over x, y, z, roll, pitch, yaw.
    #[serde(with = "BigArray")]
    pub covariance: [f64; 36],
}

impl Default for PoseWithCovariance {
    fn default() -> Self {
        PoseWithCovariance {
            pose: Pose::default(),
            covariance: [0.0; 36],
        }
    }
}

/// `geometry_msgs/msg/Twist`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    /// Linear velocity (m/s).
    pub linear: Vector3,
    /// Angular velocity (rad/s).
    pub angular: Vector3,
}

/// `geometry_msgs/msg/TwistWithCovariance`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    /// The twist.
    pub twist: Twist,
    /// Row-major 6×6.
    #[serde(with = "BigArray")]
    pub covariance: [f64; 36],
}

impl Default for TwistWithCovariance {
    fn default() -> Self {
        TwistWithCovariance {
            twist: Twist::default(),
            covariance: [0.0; 36],
        }
    }
}

/// `nav_msgs/msg/Odometry`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// Stamp, and the odometry frame.
    pub header: Header,
    /// The robot's frame.
    pub child_frame_id: String,
    /// The robot in the odometry frame.
    pub pose: PoseWithCovariance,
    /// In the child frame.
    pub twist: TwistWithCovariance,
}

/// `sensor_msgs/msg/Imu`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Imu {
    /// Stamp and the IMU's frame.
    pub header: Header,
    /// Orientation (covariance element 0 = −1: none given).
    pub orientation: Quaternion,
    /// Row-major 3×3.
    pub orientation_covariance: [f64; 9],
    /// rad/s.
    pub angular_velocity: Vector3,
    /// Row-major 3×3.
    pub angular_velocity_covariance: [f64; 9],
    /// m/s².
    pub linear_acceleration: Vector3,
    /// Row-major 3×3.
    pub linear_acceleration_covariance: [f64; 9],
}

/// `sensor_msgs/msg/NavSatStatus`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct NavSatStatus {
    /// −1 no fix, 0 fix, 1 SBAS, 2 GBAS (RTK).
    pub status: i8,
    /// Bit mask of the constellations used.
    pub service: u16,
}

impl NavSatStatus {
    /// `STATUS_NO_FIX`.
    pub const NO_FIX: i8 = -1;
}

/// `sensor_msgs/msg/NavSatFix`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NavSatFix {
    /// Stamp and the antenna's frame.
    pub header: Header,
    /// Fix status.
    pub status: NavSatStatus,
    /// Degrees, WGS 84.
    pub latitude: f64,
    /// Degrees, WGS 84.
    pub longitude: f64,
    /// Metres above the WGS 84 ellipsoid.
    pub altitude: f64,
    /// Row-major 3×3, east-north-up (m²).
    pub position_covariance: [f64; 9],
    /// 0 unknown, 1 approximated, 2 diagonal known, 3 known.
    pub position_covariance_type: u8,
}

/// `geometry_msgs/msg/Transform`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// m.
    pub translation: Vector3,
    /// Rotation.
    pub rotation: Quaternion,
}

/// `geometry_msgs/msg/TransformStamped`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    /// Stamp and the parent frame.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// The child frame in the parent's.
    pub transform: Transform,
}

/// `tf2_msgs/msg/TFMessage` (`/tf`, `/tf_static`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}

/// `nav_msgs/msg/MapMetaData`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MapMetaData {
    /// When the map was made.
    pub map_load_time: Time,
    /// m per cell.
    pub resolution: f32,
    /// Cells.
    pub width: u32,
    /// Cells.
    pub height: u32,
    /// Cell (0, 0)'s corner in the map frame.
    pub origin: Pose,
}

/// `nav_msgs/msg/OccupancyGrid`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct OccupancyGrid {
    /// Stamp and the map frame.
    pub header: Header,
    /// Size and placement.
    pub info: MapMetaData,
    /// Row-major from the origin, 0–100 occupied probability, −1 unknown.
    pub data: Vec<i8>,
}

/// `sensor_msgs/msg/PointField`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PointField {
    /// `x`, `y`, `z`, `ring`, `t`, …
    pub name: String,
    /// Byte offset in the point.
    pub offset: u32,
    /// 1 INT8, 2 UINT8, 3 INT16, 4 UINT16, 5 INT32, 6 UINT32, 7 FLOAT32, 8 FLOAT64.
    pub datatype: u8,
    /// Elements.
    pub count: u32,
}

/// `sensor_msgs/msg/PointCloud2` up to its data: decoded by serde; the data (megabytes)
/// is taken as a slice after it ([`crate::decode_cloud`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct CloudHead {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub fields: Vec<PointField>,
    pub is_bigendian: bool,
    pub point_step: u32,
    pub row_step: u32,
}
