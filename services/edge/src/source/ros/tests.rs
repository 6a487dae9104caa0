//! The assembler on bad samples: each is counted under its topic with the reason, nothing
//! panics, and the good samples after it are still used.

use super::*;
use ros2msg::{Header, Imu, PointCloud2, PointField, Time, encode, encode_cloud};

const MS: u64 = 1_000_000;
/// An epoch a little after 2020, so stamps are positive.
const T0: u64 = 1_600_000_000_000_000_000;

fn assembler() -> RosAssembler {
    let streams = RosStreams {
        lidar_in_base: vec![0.0; 6],
        columns: 8,
        ..RosStreams::default()
    };
    RosAssembler::new(streams.inputs("[test]", &BTreeMap::new()).unwrap())
}

fn header(ns: u64) -> Header {
    Header {
        stamp: Time::from_ns(ns),
        frame_id: "lidar".into(),
    }
}

fn odometry(ns: u64, x: f64) -> Vec<u8> {
    let mut m = Odometry {
        header: header(ns),
        ..Odometry::default()
    };
    m.pose.pose.position.x = x;
    encode(&m)
}

/// A cloud of 32 points around the lidar, with the given float32 fields at 0, 4, 8.
fn cloud(ns: u64, names: [&str; 3]) -> Vec<u8> {
    let data: Vec<u8> = (0..32)
        .flat_map(|i| {
            let a = i as f32 * 0.2;
            [5.0 * a.cos(), 5.0 * a.sin(), (i % 4) as f32 * 0.3]
                .into_iter()
                .flat_map(f32::to_le_bytes)
        })
        .collect();
    let fields = names
        .iter()
        .zip([0, 4, 8])
        .map(|(name, offset)| PointField {
            name: (*name).to_owned(),
            offset,
            datatype: 7,
            count: 1,
        })
        .collect();
    encode_cloud(&PointCloud2 {
        header: header(ns),
        height: 1,
        width: 32,
        fields,
        is_bigendian: false,
        point_step: 12,
        row_step: 12 * 32,
        data: &data,
        is_dense: true,
    })
}

fn drain(a: &mut RosAssembler) -> (usize, usize) {
    let (mut odometry, mut scans) = (0, 0);
    while let Some(e) = a.pop() {
        match e {
            SourceEvent::Odometry(_) => odometry += 1,
            SourceEvent::Scan(_) => scans += 1,
        }
    }
    (odometry, scans)
}

#[test]
fn a_wrong_typed_or_truncated_odometry_sample_is_counted_and_the_next_is_used() {
    let mut a = assembler();
    a.push("/odom", ODOMETRY_TYPE, &odometry(T0, 0.0));
    // An IMU message's bytes where odometry should be: they do not decode as odometry.
    a.push("/odom", ODOMETRY_TYPE, &encode(&Imu::default()));
    // The key says another type.
    a.push("/odom", IMU_TYPE, &odometry(T0 + 50 * MS, 0.05));
    let good = odometry(T0 + 100 * MS, 0.1);
    a.push("/odom", ODOMETRY_TYPE, &good[..good.len() / 2]);
    a.push("/odom", ODOMETRY_TYPE, &odometry(T0 + 200 * MS, 0.2));
    assert_eq!(drain(&mut a), (2, 0));
    let counts = a.counts();
    assert_eq!(counts.used.get("/odom"), Some(&2));
    let refused: u64 = counts
        .refused
        .iter()
        .filter(|(k, _)| k.starts_with("/odom: "))
        .map(|(_, n)| n)
        .sum();
    assert_eq!(refused, 3, "{counts:?}");
    assert_eq!(
        counts
            .refused
            .get("/odom: type sensor_msgs/msg/Imu, not nav_msgs/msg/Odometry"),
        Some(&1),
        "{counts:?}"
    );
}

#[test]
fn a_cloud_without_xyz_is_counted_and_the_next_cloud_is_a_scan() {
    let mut a = assembler();
    for i in 0..=10 {
        a.push("/odom", ODOMETRY_TYPE, &odometry(T0 + i * 100 * MS, 0.0));
    }
    a.push(
        "/points",
        CLOUD_TYPE,
        &cloud(T0 + 100 * MS, ["a", "b", "c"]),
    );
    a.push("/points", CLOUD_TYPE, &[0, 1, 0, 0, 9]);
    a.push(
        "/points",
        CLOUD_TYPE,
        &cloud(T0 + 300 * MS, ["x", "y", "z"]),
    );
    a.push("/odom", ODOMETRY_TYPE, &odometry(T0 + 1100 * MS, 0.0));
    let (_, scans) = drain(&mut a);
    assert_eq!(scans, 1);
    let counts = a.counts();
    assert_eq!(counts.used.get("/points"), Some(&1), "{counts:?}");
    let refused: Vec<&String> = counts
        .refused
        .keys()
        .filter(|k| k.starts_with("/points: "))
        .collect();
    assert_eq!(refused.len(), 2, "{counts:?}");
    assert!(refused.iter().any(|k| k.contains('x')), "{counts:?}");
}
