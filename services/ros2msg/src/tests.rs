//! Bad input: every malformed sample is an error, never a panic or a read out of bounds.

use super::*;
use proptest::prelude::*;

fn cloud_sample(fields: Vec<PointField>, point_step: u32, width: u32, data: &[u8]) -> Vec<u8> {
    encode_cloud(&PointCloud2 {
        header: Header::default(),
        height: 1,
        width,
        fields,
        is_bigendian: false,
        point_step,
        row_step: point_step * width,
        data,
        is_dense: true,
    })
}

fn f32_field(name: &str, offset: u32) -> PointField {
    PointField {
        name: name.into(),
        offset,
        datatype: 7,
        count: 1,
    }
}

fn xyz_fields() -> Vec<PointField> {
    vec![f32_field("x", 0), f32_field("y", 4), f32_field("z", 8)]
}

#[test]
fn a_cloud_round_trips_and_reads_its_points() {
    let data: Vec<u8> = [1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let sample = cloud_sample(xyz_fields(), 12, 2, &data);
    let cloud = decode_cloud(&sample).expect("a cloud");
    let points = CloudPoints::from_cloud(&cloud).expect("points");
    assert_eq!(points.xyz, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    assert_eq!((points.ring, points.offset_ns), (None, None));
}

#[test]
fn truncated_and_foreign_samples_are_errors() {
    let fix = NavSatFix {
        header: Header::default(),
        status: NavSatStatus::default(),
        latitude: 1.0,
        longitude: 2.0,
        altitude: 3.0,
        position_covariance: [0.0; 9],
        position_covariance_type: 0,
    };
    let sample = encode(&fix);
    for len in 0..sample.len() - 1 {
        assert!(decode::<NavSatFix>(&sample[..len]).is_err(), "{len} bytes");
    }
    let mut xcdr2 = sample.clone();
    xcdr2[1] = 0x07;
    assert_eq!(
        decode::<NavSatFix>(&xcdr2),
        Err(DecodeError::Encapsulation(0x0007))
    );
    // CDR carries no type: another type's bytes may decode (a NavSatFix here is too short
    // for a cloud, but need not be). The sources check the type the key or the recording
    // names before decoding.
    assert!(decode_cloud(&sample[..20]).is_err());
}

#[test]
fn clouds_whose_layout_does_not_fit_are_errors() {
    let data = [0u8; 24];
    let read = |fields, step, width| {
        let sample = cloud_sample(fields, step, width, &data);
        CloudPoints::from_cloud(&decode_cloud(&sample).expect("a cloud"))
    };
    let no_z = vec![f32_field("x", 0), f32_field("y", 4)];
    assert_eq!(read(no_z, 12, 2), Err(CloudError::MissingField("z")));
    // A field past the point's end, more points than the data holds, x as an integer.
    assert!(matches!(
        read(xyz_fields(), 10, 2),
        Err(CloudError::Layout(_))
    ));
    assert!(matches!(
        read(xyz_fields(), 12, 3),
        Err(CloudError::Layout(_))
    ));
    let mut int_x = xyz_fields();
    int_x[0].datatype = 6;
    assert!(matches!(
        read(int_x, 12, 2),
        Err(CloudError::FieldType { .. })
    ));
}

proptest! {
    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let mut sample = vec![0x00, 0x01, 0x00, 0x00];
        sample.extend(bytes);
        let _ = decode::<Odometry>(&sample);
        let _ = decode::<TfMessage>(&sample);
        if let Ok(cloud) = decode_cloud(&sample) {
            let _ = CloudPoints::from_cloud(&cloud);
        }
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

/// The drivers' layouts the fast loop takes: (fields, point_step).
fn fast_layouts() -> Vec<(Vec<PointField>, u32)> {
    let xyz_at = |at: u32| {
        vec![
            field("x", at, 7),
            field("y", at + 4, 7),
            field("z", at + 8, 7),
        ]
    };
    let with = |mut fields: Vec<PointField>, more: &[(&str, u32, u8)]| {
        fields.extend(
            more.iter()
                .map(|&(name, at, datatype)| field(name, at, datatype)),
        );
        fields
    };
    vec![
        // Ouster (ouster-ros): u32 `t` in ns, u16 `ring`.
        (
            with(
                xyz_at(0),
                &[("intensity", 16, 7), ("t", 20, 6), ("ring", 24, 4)],
            ),
            32,
        ),
        // Velodyne (velodyne_pointcloud): u16 `ring`, f32 `time` in s; unaligned points.
        (
            with(
                xyz_at(0),
                &[("intensity", 12, 7), ("ring", 16, 4), ("time", 18, 7)],
            ),
            22,
        ),
        // Hesai: f64 `timestamp`, absolute or not.
        (
            with(
                xyz_at(0),
                &[("intensity", 12, 7), ("timestamp", 16, 8), ("ring", 24, 4)],
            ),
            26,
        ),
        // x, y, z alone, not at the point's start, in an odd-sized point.
        (xyz_at(4), 17),
    ]
}

fn same_f32(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

proptest! {
    /// The fast loop reads the same points as the field-by-field one, for any bytes in the
    /// points (NaN, infinities, times past 1e18 ns) and rows padded or not.
    #[test]
    fn the_fast_loop_reads_what_the_generic_one_does(
        layout in 0..4usize,
        width in 0..40u32,
        height in 0..4u32,
        row_padding in prop_oneof![Just(0u32), 1..9u32],
        stamp_sec in any::<i32>(),
        seed in any::<u64>(),
    ) {
        let (fields, step) = fast_layouts().swap_remove(layout);
        let row_step = step * width + row_padding;
        let mut state = seed | 1;
        // xorshift: random bytes, so that every bit pattern of every field turns up.
        let data: Vec<u8> = (0..row_step * height)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                state as u8
            })
            .collect();
        let cloud = PointCloud2 {
            header: Header {
                stamp: Time { sec: stamp_sec, nanosec: 0 },
                frame_id: String::new(),
            },
            height,
            width,
            fields,
            is_bigendian: false,
            point_step: step,
            row_step,
            data: &data,
            is_dense: false,
        };
        prop_assert!(CloudPoints::has_fast_layout(&cloud));
        let fast = CloudPoints::from_cloud(&cloud).expect("points");
        let generic = CloudPoints::from_cloud_generic(&cloud).expect("points");
        prop_assert_eq!(fast.xyz.len(), (width * height) as usize);
        prop_assert_eq!(fast.xyz.len(), generic.xyz.len());
        for (f, g) in fast.xyz.iter().zip(&generic.xyz) {
            prop_assert!(f.iter().zip(g).all(|(a, b)| same_f32(*a, *b)), "{f:?} vs {g:?}");
        }
        prop_assert_eq!(fast.ring, generic.ring);
        prop_assert_eq!(fast.offset_ns, generic.offset_ns);
    }
}

#[test]
fn other_layouts_take_the_generic_loop() {
    let (fields, step) = fast_layouts().swap_remove(0);
    let data = vec![0u8; step as usize];
    let cloud = PointCloud2 {
        header: Header::default(),
        height: 1,
        width: 1,
        fields,
        is_bigendian: false,
        point_step: step,
        row_step: step,
        data: &data,
        is_dense: true,
    };
    assert!(CloudPoints::has_fast_layout(&cloud));
    let mut big_endian = cloud.clone();
    big_endian.is_bigendian = true;
    let mut f64_x = cloud.clone();
    f64_x.fields[0].datatype = 8;
    let mut y_first = cloud.clone();
    (y_first.fields[0].offset, y_first.fields[1].offset) = (4, 0);
    let mut u8_ring = cloud.clone();
    u8_ring.fields[5].datatype = 2;
    let mut i32_time = cloud.clone();
    i32_time.fields[4].datatype = 5;
    for other in [big_endian, f64_x, y_first, u8_ring, i32_time] {
        assert!(!CloudPoints::has_fast_layout(&other), "{:?}", other.fields);
        assert!(CloudPoints::from_cloud(&other).is_ok());
    }
}

#[test]
fn rows_without_points_are_no_points() {
    // 4 billion rows of no point in no data: read at once, not row by row.
    let cloud = PointCloud2 {
        header: Header::default(),
        height: u32::MAX,
        width: 0,
        fields: xyz_fields(),
        is_bigendian: false,
        point_step: 12,
        row_step: 0,
        data: &[],
        is_dense: true,
    };
    let started = std::time::Instant::now();
    let points = CloudPoints::from_cloud(&cloud).expect("no points");
    assert!(points.xyz.is_empty());
    assert!(started.elapsed() < std::time::Duration::from_secs(1));
}
