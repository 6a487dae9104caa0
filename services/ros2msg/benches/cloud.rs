//! Speed of taking a lidar's cloud off the wire, one core: an OS-1-128 frame (128 × 1024
//! points, Ouster's 32-byte `PointCloud2` layout with `t` and `ring`), decoded from its CDR
//! sample and read into points. Aim (issue 13): ≤ 1 ms.
//!
//!     cargo bench -p ros2msg --bench cloud

use ros2msg::{CloudPoints, Header, PointCloud2, PointField, decode_cloud, encode_cloud};

fn main() {
    divan::main();
}

fn ouster_frame() -> Vec<u8> {
    let (rows, columns, step) = (128u32, 1024u32, 32u32);
    let mut data = Vec::with_capacity((rows * columns * step) as usize);
    for row in 0..rows {
        for column in 0..columns {
            let azimuth = column as f32 / columns as f32 * std::f32::consts::TAU;
            let elevation = (row as f32 - 64.0) * 0.006;
            let range = 5.0 + (row * 7 + column) as f32 % 30.0;
            let mut point = [0u8; 32];
            let xyz = [
                range * azimuth.cos(),
                range * azimuth.sin(),
                range * elevation,
            ];
            for (i, v) in xyz.iter().enumerate() {
                point[i * 4..i * 4 + 4].copy_from_slice(&v.to_le_bytes());
            }
            point[20..24].copy_from_slice(&(column * 97_656).to_le_bytes());
            point[24..26].copy_from_slice(&(row as u16).to_le_bytes());
            data.extend_from_slice(&point);
        }
    }
    let field = |name: &str, offset, datatype| PointField {
        name: name.into(),
        offset,
        datatype,
        count: 1,
    };
    encode_cloud(&PointCloud2 {
        header: Header::default(),
        height: rows,
        width: columns,
        fields: vec![
            field("x", 0, 7),
            field("y", 4, 7),
            field("z", 8, 7),
            field("intensity", 16, 7),
            field("t", 20, 6),
            field("ring", 24, 4),
        ],
        is_bigendian: false,
        point_step: step,
        row_step: step * columns,
        data: &data,
        is_dense: true,
    })
}

#[divan::bench]
fn os1_128_frame_to_points(bencher: divan::Bencher) {
    let sample = ouster_frame();
    bencher.bench_local(|| {
        let cloud = decode_cloud(&sample).expect("a cloud");
        CloudPoints::from_cloud(&cloud).expect("points")
    });
}

#[divan::bench]
fn os1_128_frame_decode_only(bencher: divan::Bencher) {
    let sample = ouster_frame();
    bencher.bench_local(|| decode_cloud(&sample).expect("a cloud").data.len());
}
