//! The ROS 2 types levelmap reads and writes, as rmw_zenoh names them on its keys: the type
//! name and its RIHS01 type hash (REP 2011; the same since ROS 2 Iron, checked against
//! rosbags' `hash_rihs01` in `tests/rosbags_cdr.rs`). A subscriber on rmw_zenoh takes only
//! samples whose key carries its type's hash.

/// A ROS 2 message type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RosType {
    /// `package/msg/Name`.
    pub name: &'static str,
    /// `RIHS01_<sha256 of the type description>`.
    pub hash: &'static str,
}

/// `sensor_msgs/msg/PointCloud2`.
pub const POINT_CLOUD2: RosType = RosType {
    name: "sensor_msgs/msg/PointCloud2",
    hash: "RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5",
};
/// `nav_msgs/msg/Odometry`.
pub const ODOMETRY: RosType = RosType {
    name: "nav_msgs/msg/Odometry",
    hash: "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
};
/// `sensor_msgs/msg/Imu`.
pub const IMU: RosType = RosType {
    name: "sensor_msgs/msg/Imu",
    hash: "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b",
};
/// `sensor_msgs/msg/NavSatFix`.
pub const NAV_SAT_FIX: RosType = RosType {
    name: "sensor_msgs/msg/NavSatFix",
    hash: "RIHS01_62223ab3fe210a15976021da7afddc9e200dc9ec75231c1b6a557fc598a65404",
};
/// `tf2_msgs/msg/TFMessage`.
pub const TF_MESSAGE: RosType = RosType {
    name: "tf2_msgs/msg/TFMessage",
    hash: "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
};
/// `nav_msgs/msg/OccupancyGrid`.
pub const OCCUPANCY_GRID: RosType = RosType {
    name: "nav_msgs/msg/OccupancyGrid",
    hash: "RIHS01_8d348150c12913a31ee0ec170fbf25089e4745d17035792a1ba94d6f0bc0cfc7",
};

/// Every type above.
pub const ALL: [RosType; 6] = [
    POINT_CLOUD2,
    ODOMETRY,
    IMU,
    NAV_SAT_FIX,
    TF_MESSAGE,
    OCCUPANCY_GRID,
];
