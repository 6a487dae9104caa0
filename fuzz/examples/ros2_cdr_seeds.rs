//! Writes the seed inputs of the `ros2_cdr` target into the folder given (README.md,
//! "Corpora"): one sample of each message the edge's ROS 2 sources decode, encoded by
//! `ros2msg::encode`/`encode_cloud` (little-endian CDR), and clouds in the drivers' layouts
//! (Ouster, Velodyne, Hesai: the fast loop) and two others (big-endian data; f64 x, y, z
//! with a u8 ring and an i32 time: the field-by-field loop). Deterministic.
//!
//!     cargo run --manifest-path fuzz/Cargo.toml --example ros2_cdr_seeds -- DIR

use ros2msg::{
    CloudPoints, Header, Imu, NavSatFix, NavSatStatus, Odometry, PointCloud2, PointField, Pose,
    PoseWithCovariance, Quaternion, TfMessage, Time, Transform, TransformStamped, Twist,
    TwistWithCovariance, Vector3, decode, decode_cloud, encode, encode_cloud,
};
use std::path::Path;

fn header(frame: &str) -> Header {
    Header {
        stamp: Time {
            sec: 1_700_000_000,
            nanosec: 123_456_789,
        },
        frame_id: frame.into(),
    }
}

fn vector(x: f64, y: f64, z: f64) -> Vector3 {
    Vector3 { x, y, z }
}

fn rotation() -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.38268343236,
        w: 0.92387953251,
    }
}

fn field(name: &str, offset: u32, datatype: u8) -> PointField {
    PointField {
        name: name.into(),
        offset,
        datatype,
        count: 1,
    }
}

/// A cloud of `rows` × `columns` points whose bytes come from `point(row, column, step)`.
fn cloud(
    fields: Vec<PointField>,
    step: u32,
    (rows, columns): (u32, u32),
    big_endian: bool,
    point: impl Fn(u32, u32) -> Vec<u8>,
) -> Vec<u8> {
    let data: Vec<u8> = (0..rows)
        .flat_map(|row| (0..columns).map(move |column| (row, column)))
        .flat_map(|(row, column)| {
            let mut bytes = point(row, column);
            bytes.resize(step as usize, 0);
            bytes
        })
        .collect();
    encode_cloud(&PointCloud2 {
        header: header("os_lidar"),
        height: rows,
        width: columns,
        fields,
        is_bigendian: big_endian,
        point_step: step,
        row_step: step * columns,
        data: &data,
        is_dense: false,
    })
}

/// Little-endian bytes of the values, one after another.
macro_rules! le {
    ($($v:expr),*) => {{
        let mut bytes = Vec::new();
        $(bytes.extend_from_slice(&$v.to_le_bytes());)*
        bytes
    }};
}

fn main() {
    let dir = std::env::args()
        .nth(1)
        .expect("usage: ros2_cdr_seeds DIR (the folder to write the seeds into)");
    let dir = Path::new(&dir);
    std::fs::create_dir_all(dir).expect("seed folder");
    let write = |name: &str, sample: Vec<u8>| {
        // Each seed is what it is meant to be: a message, or a cloud with its points.
        let decodes = match name {
            "imu" => decode::<Imu>(&sample).is_ok(),
            "navsatfix" => decode::<NavSatFix>(&sample).is_ok(),
            "odometry" => decode::<Odometry>(&sample).is_ok(),
            "tf" => decode::<TfMessage>(&sample).is_ok(),
            _ => decode_cloud(&sample).is_ok_and(|c| CloudPoints::from_cloud(&c).is_ok()),
        };
        assert!(decodes, "seed {name} does not decode");
        std::fs::write(dir.join(name), sample).expect("a seed written");
    };

    let mut covariance = [0.0; 9];
    covariance[0] = 0.01;
    write(
        "imu",
        encode(&Imu {
            header: header("imu_link"),
            orientation: rotation(),
            orientation_covariance: covariance,
            angular_velocity: vector(0.01, -0.02, 0.3),
            angular_velocity_covariance: covariance,
            linear_acceleration: vector(0.1, 0.2, 9.81),
            linear_acceleration_covariance: [-1.0; 9],
        }),
    );
    write(
        "navsatfix",
        encode(&NavSatFix {
            header: header("gps"),
            status: NavSatStatus {
                status: 2,
                service: 1,
            },
            latitude: 48.137154,
            longitude: 11.576124,
            altitude: 519.5,
            position_covariance: [0.04, 0.0, 0.0, 0.0, 0.04, 0.0, 0.0, 0.0, 0.09],
            position_covariance_type: 2,
        }),
    );
    let mut covariance = [0.0; 36];
    covariance[0] = 0.001;
    covariance[35] = 0.002;
    write(
        "odometry",
        encode(&Odometry {
            header: header("odom"),
            child_frame_id: "base_link".into(),
            pose: PoseWithCovariance {
                pose: Pose {
                    position: vector(12.5, -3.25, 0.75),
                    orientation: rotation(),
                },
                covariance,
            },
            twist: TwistWithCovariance {
                twist: Twist {
                    linear: vector(1.2, 0.0, 0.0),
                    angular: vector(0.0, 0.0, 0.1),
                },
                covariance,
            },
        }),
    );
    let transform = |parent: &str, child: &str, x| TransformStamped {
        header: header(parent),
        child_frame_id: child.into(),
        transform: Transform {
            translation: vector(x, 0.0, 0.3),
            rotation: rotation(),
        },
    };
    write(
        "tf",
        encode(&TfMessage {
            transforms: vec![
                transform("odom", "base_link", 2.0),
                transform("base_link", "os_sensor", 0.1),
            ],
        }),
    );

    let xyz = |row: u32, column: u32| {
        let (r, c) = (row as f32, column as f32);
        [5.0 + c, -2.0 + r, 0.5 * r - 1.0]
    };
    // Ouster (ouster-ros): intensity, u32 `t` (ns), u16 `ring`; 32-byte points.
    write(
        "cloud-ouster",
        cloud(
            vec![
                field("x", 0, 7),
                field("y", 4, 7),
                field("z", 8, 7),
                field("intensity", 16, 7),
                field("t", 20, 6),
                field("ring", 24, 4),
            ],
            32,
            (4, 4),
            false,
            |row, column| {
                let [x, y, z] = xyz(row, column);
                le!(x, y, z, 0f32, 40f32, column * 97_656, row as u16)
            },
        ),
    );
    // Velodyne: u16 `ring`, f32 `time` (s, relative); 22-byte points.
    write(
        "cloud-velodyne",
        cloud(
            vec![
                field("x", 0, 7),
                field("y", 4, 7),
                field("z", 8, 7),
                field("intensity", 12, 7),
                field("ring", 16, 4),
                field("time", 18, 7),
            ],
            22,
            (1, 8),
            false,
            |row, column| {
                let [x, y, z] = xyz(row, column);
                le!(x, y, z, 12f32, (column % 16) as u16, column as f32 * -1e-4)
            },
        ),
    );
    // Hesai: f64 `timestamp` (s, absolute).
    write(
        "cloud-hesai",
        cloud(
            vec![
                field("x", 0, 7),
                field("y", 4, 7),
                field("z", 8, 7),
                field("intensity", 12, 7),
                field("timestamp", 16, 8),
                field("ring", 24, 4),
            ],
            26,
            (1, 6),
            false,
            |row, column| {
                let [x, y, z] = xyz(row, column);
                le!(
                    x,
                    y,
                    z,
                    3f32,
                    1_700_000_000.1 + column as f64 * 1e-5,
                    column as u16
                )
            },
        ),
    );
    // Big-endian data, x, y, z only.
    write(
        "cloud-big-endian",
        cloud(
            vec![field("x", 0, 7), field("y", 4, 7), field("z", 8, 7)],
            16,
            (2, 3),
            true,
            |row, column| {
                let [x, y, z] = xyz(row, column);
                [x, y, z].iter().flat_map(|v| v.to_be_bytes()).collect()
            },
        ),
    );
    // f64 x, y, z, a u8 `channel` and an i32 `timestamp` (ns).
    write(
        "cloud-f64",
        cloud(
            vec![
                field("x", 0, 8),
                field("y", 8, 8),
                field("z", 16, 8),
                field("channel", 24, 2),
                field("timestamp", 25, 5),
            ],
            32,
            (2, 2),
            false,
            |row, column| {
                let [x, y, z] = xyz(row, column).map(f64::from);
                le!(x, y, z, row as u8, -(column as i32) * 50_000)
            },
        ),
    );
}
