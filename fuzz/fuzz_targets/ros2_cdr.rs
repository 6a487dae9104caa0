//! A ROS 2 sample (the CDR encapsulation header, then CDR) as the edge's ROS 2 sources take
//! it from the bus or a recording (`edge/src/source/ros.rs`): the same bytes through every
//! decoder they run on a sample, `Imu`, `NavSatFix`, `TFMessage`, `Odometry`, and
//! `PointCloud2` then its points (`CloudPoints::from_cloud`, the fast loop or the
//! field-by-field one). CDR carries no type, so any bytes may be any message: each decoder
//! sees all of them.
#![no_main]

use libfuzzer_sys::fuzz_target;
use ros2msg::{
    CloudPoints, Imu, NavSatFix, Odometry, TfMessage, decode, decode_cloud, encode, encode_cloud,
};
use serde::Serialize;
use serde::de::DeserializeOwned;

fuzz_target!(|data: &[u8]| {
    re_encodes::<Imu>(data);
    re_encodes::<NavSatFix>(data);
    re_encodes::<TfMessage>(data);
    re_encodes::<Odometry>(data);
    let Ok(cloud) = decode_cloud(data) else {
        return;
    };
    // Written back (little endian), the cloud reads the same: the head and the data.
    assert_eq!(
        decode_cloud(&encode_cloud(&cloud)).as_ref(),
        Ok(&cloud),
        "the cloud re-encoded differs"
    );
    let Ok(points) = CloudPoints::from_cloud(&cloud) else {
        return;
    };
    // A point per pixel, and a ring and a time per point when there are any.
    let n = cloud.width as usize * cloud.height as usize;
    assert_eq!(points.xyz.len(), n);
    assert!(points.ring.as_ref().is_none_or(|ring| ring.len() == n));
    assert!(points.offset_ns.as_ref().is_none_or(|t| t.len() == n));
});

/// A message that decodes encodes to a sample that decodes to it again (compared as bytes,
/// so that NaNs compare).
fn re_encodes<T: Serialize + DeserializeOwned>(data: &[u8]) {
    let Ok(message) = decode::<T>(data) else {
        return;
    };
    let sample = encode(&message);
    let again: T = decode(&sample).expect("a message encoded here decodes");
    assert!(encode(&again) == sample, "the message re-encoded differs");
}
