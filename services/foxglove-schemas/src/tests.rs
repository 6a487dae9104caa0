use super::*;
use leveling::Beam;
use slam::gnss::FixStatus;
use slam::nalgebra::{Matrix2, Matrix3, Vector2, Vector3 as V3};

fn beam(bearing_rad: f64, range_m: Option<f32>) -> Beam {
    Beam {
        bearing_rad: bearing_rad as f32,
        range_m,
        sensor_xy_m: [0.0, 0.0],
        ground_to_m: None,
    }
}

#[test]
fn a_pose_turns_about_z_and_a_grid_keeps_the_rows_and_cells_of_the_occupancy_grid() {
    let p = pose(&Pose2::new(1.0, -2.0, std::f64::consts::FRAC_PI_2));
    let q = p.orientation.unwrap();
    assert!((q.z - 0.5f64.sqrt()).abs() < 1e-12 && (q.w - 0.5f64.sqrt()).abs() < 1e-12);
    assert_eq!(p.position.unwrap().y, -2.0);

    let g = OccupancyGrid {
        resolution_m: 0.1,
        origin_m: [-1.0, 2.0],
        width: 3,
        height: 2,
        cells: vec![-1, 0, 100, 50, -1, 0],
        occupied_percent: 65,
        free_percent: 25,
    };
    let out = grid(map_frame("park"), &g, 1_500_000_000);
    assert_eq!(out.frame_id, "park/map");
    assert_eq!(
        (out.column_count, out.row_stride, out.cell_stride),
        (3, 6, 2)
    );
    // Row-major from the origin's row, as the occupancy grid: -1 as 0xff; then each cell's
    // state (0 free, 1 unknown, 2 occupied: 50 % is between the thresholds, unknown).
    let occupancy: Vec<u8> = out.data.iter().step_by(2).copied().collect();
    let state: Vec<u8> = out.data.iter().skip(1).step_by(2).copied().collect();
    assert_eq!(occupancy, [0xff, 0, 100, 50, 0xff, 0]);
    assert_eq!(state, [1, 0, 2, 1, 1, 0]);
    let origin = out.pose.unwrap().position.unwrap();
    assert_eq!((origin.x, origin.y), (-1.0, 2.0));
    use packed_element_field::NumericType;
    let fields: Vec<_> = out
        .fields
        .iter()
        .map(|f| (f.name.as_str(), f.offset, f.r#type()))
        .collect();
    assert_eq!(
        fields,
        [
            ("occupancy", 0, NumericType::Int8),
            ("state", 1, NumericType::Uint8)
        ]
    );
    assert_eq!(out.timestamp.unwrap(), Timestamp::new(1, 500_000_000));
}

#[test]
fn a_spinning_scan_is_drawn_on_the_whole_turn_each_return_at_its_nearest_bearing() {
    // Eight beams a turn; one shifted by a third of a step, one without a return.
    let step = PI / 4.0;
    let mut beams: Vec<Beam> = (0..8)
        .map(|k| beam(-PI + step * k as f64, Some(1.0 + k as f32)))
        .collect();
    beams[2] = beam(-PI + step * 2.0 + step / 3.0, Some(3.0));
    beams[5].range_m = None;
    let scan = LeveledScan { stamp_ns: 7, beams };
    let out = laser_scan(map_frame("park"), &Pose2::new(2.0, 3.0, 0.5), &scan);
    assert_eq!(out.start_angle, -PI);
    assert!((out.end_angle - (-PI + 7.0 * step)).abs() < 1e-12);
    assert_eq!(out.ranges.len(), 8);
    for (k, r) in out.ranges.iter().enumerate() {
        if k == 5 {
            assert!(r.is_nan(), "no return is NaN, not {r}");
        } else {
            assert_eq!(*r, 1.0 + k as f64, "bin {k}");
        }
    }
    let origin = out.pose.unwrap().position.unwrap();
    assert_eq!(
        (origin.x, origin.y, out.timestamp),
        (2.0, 3.0, Some(timestamp(7)))
    );
}

#[test]
fn a_half_turn_scan_keeps_its_span_and_the_nearer_of_two_returns_on_one_bearing() {
    // A 2D scanner's 180° over 181 beams, as the Freiburg logs: bins fall on the beams.
    let mut beams: Vec<Beam> = (0..181)
        .map(|k| beam((k as f64 - 90.0).to_radians(), Some(10.0)))
        .collect();
    // The last beam, at +90°, nearer than its neighbours.
    beams[180] = beam(PI / 2.0, Some(4.0));
    beams[90] = beam(0.0, Some(5.0));
    beams.push(beam(0.001, Some(2.5)));
    beams.push(beam(0.0, None));
    let scan = LeveledScan { stamp_ns: 0, beams };
    let out = laser_scan(map_frame("p"), &Pose2::IDENTITY, &scan);
    assert!((out.start_angle + PI / 2.0).abs() < 1e-6);
    assert!((out.end_angle - PI / 2.0).abs() < 1e-6);
    let n = out.ranges.len();
    let step = (out.end_angle - out.start_angle) / (n - 1) as f64;
    let bin = |b: f64| ((b - out.start_angle) / step).round() as usize;
    assert_eq!(out.ranges[bin(0.0)], 2.5, "the nearer of the two at 0 rad");
    assert_eq!(out.ranges[bin(PI / 2.0)], 4.0);
    assert_eq!(out.ranges[0], 10.0);
}

#[test]
fn a_cloud_packs_each_point_and_its_class_and_leaves_invalid_points_out() {
    let cloud = ClassifiedCloud {
        points_m: vec![[1.0, -2.0, 0.5], [9.0, 9.0, 9.0], [0.25, 0.0, -1.5]],
        classes: vec![
            PointClass::Landmark,
            PointClass::Invalid,
            PointClass::Ground,
        ],
        ..Default::default()
    };
    let out = point_cloud(
        odom_frame("park", "r1"),
        &Pose2::new(1.0, 0.0, 0.0),
        &cloud,
        5,
    );
    assert_eq!(out.frame_id, "park/r1/odom");
    assert_eq!(out.point_stride, CLOUD_POINT_STRIDE);
    assert_eq!(out.data.len(), 2 * CLOUD_POINT_STRIDE as usize);
    let f = |at: usize| f32::from_le_bytes(out.data[at..at + 4].try_into().unwrap());
    assert_eq!((f(0), f(4), f(8), out.data[12]), (1.0, -2.0, 0.5, 2));
    assert_eq!((f(13), f(17), f(21), out.data[25]), (0.25, 0.0, -1.5, 1));
    let names: Vec<_> = out
        .fields
        .iter()
        .map(|f| (f.name.as_str(), f.offset))
        .collect();
    assert_eq!(names, [("x", 0), ("y", 4), ("z", 8), ("class", 12)]);
}

#[test]
fn a_fix_keeps_its_position_and_covariance_and_one_without_a_position_is_none() {
    let mut fix = GpsFix {
        stamp_ns: 3,
        position: Geodetic {
            latitude_deg: 48.0,
            longitude_deg: 7.8,
            height_m: 250.0,
        },
        covariance_m2: Some(Matrix3::new(4.0, 0.5, 0.0, 0.5, 9.0, 0.0, 0.0, 0.0, 16.0)),
        status: FixStatus::Fix,
        antenna_offset_m: V3::zeros(),
    };
    let out = location_fix(map_frame("park"), &fix).unwrap();
    assert_eq!(
        (out.latitude, out.longitude, out.altitude),
        (48.0, 7.8, 250.0)
    );
    assert_eq!(
        out.position_covariance,
        [4.0, 0.5, 0.0, 0.5, 9.0, 0.0, 0.0, 0.0, 16.0]
    );
    use location_fix::PositionCovarianceType as Kind;
    assert_eq!(out.position_covariance_type(), Kind::Known);

    fix.covariance_m2 = None;
    fix.status = FixStatus::RtkFixed;
    let out = location_fix(map_frame("park"), &fix).unwrap();
    assert_eq!(out.position_covariance_type(), Kind::Approximated);
    assert!((out.position_covariance[0] - 0.03f64.powi(2)).abs() < 1e-12);

    fix.status = FixStatus::NoFix;
    assert!(location_fix(map_frame("park"), &fix).is_none());
}

#[test]
fn an_observed_fix_is_where_its_east_and_north_put_it_from_the_datum() {
    let datum = GeoDatum {
        origin: Geodetic {
            latitude_deg: 48.0,
            longitude_deg: 7.8,
            height_m: 250.0,
        },
    };
    let observation = GpsObservation {
        position_m: Vector2::new(100.0, -50.0),
        covariance_m2: Matrix2::new(1.0, 0.1, 0.1, 4.0),
        lever_arm_m: Vector2::zeros(),
    };
    let out = observed_fix(map_frame("park"), &datum, &observation, 9);
    let back = datum.geodetic_to_enu(&Geodetic {
        latitude_deg: out.latitude,
        longitude_deg: out.longitude,
        height_m: out.altitude,
    });
    assert!(
        (back.x - 100.0).abs() < 1e-6 && (back.y + 50.0).abs() < 1e-6,
        "{back}"
    );
    assert_eq!(out.position_covariance[..5], [1.0, 0.1, 0.0, 0.1, 4.0]);
    assert_eq!(out.position_covariance[8], 4.0);
}
