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
