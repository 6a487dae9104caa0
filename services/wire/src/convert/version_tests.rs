use super::*;

fn version() -> MapVersion {
    let node = |i: u64, robot: &str| VersionNode {
        robot: robot.into(),
        chain_id: 0x5eed,
        node_seq: i,
        stamp_ns: 1_700_000_000_000_000_000 + i,
        pose: Pose2::new(1.5 * i as f64, -2.0, 0.25),
        bearings_rad: vec![-0.5, 0.0, 0.5],
        ranges_m: vec![3.0, 0.0, 12.25],
    };
    MapVersion {
        fleet: "park".into(),
        number: 3,
        created_ns: 1_700_000_100_000_000_000,
        datum: Some(GeoDatum {
            origin: Geodetic {
                latitude_deg: 52.39,
                longitude_deg: 9.71,
                height_m: 55.0,
            },
        }),
        edges: 4,
        gps_edges: 2,
        loop_closures: 1,
        nodes: vec![node(0, "r0"), node(1, "r0"), node(0, "r1")],
        grid: OccupancyGrid {
            resolution_m: 0.1,
            origin_m: [-3.2, 1.0],
            width: 3,
            height: 2,
            cells: vec![-1, 0, 100, 33, -1, 70],
            occupied_percent: 65,
            free_percent: 35,
        },
        imported_from: Some(VersionOrigin {
            fleet: "campus".into(),
            number: 7,
            imported_ns: 9,
        }),
    }
}

/// A file around `msg` with a correct checksum: the field checks are what refuse it.
fn file_of(msg: &v1::MapVersion) -> Vec<u8> {
    let body = msg.encode_to_vec();
    v1::MapVersionFile {
        format_version: MAP_VERSION_FORMAT,
        message: MAP_VERSION_MESSAGE.into(),
        map_version_crc32: crc32(&body),
        map_version: body,
    }
    .encode_to_vec()
}

fn grid(m: &mut v1::MapVersion) -> &mut v1::VersionGrid {
    m.grid.as_mut().unwrap()
}

fn refused(edit: impl FnOnce(&mut v1::MapVersion)) -> WireError {
    let mut msg = map_version_to_wire(&version());
    edit(&mut msg);
    decode_map_version_file(&file_of(&msg)).expect_err("refused")
}

#[test]
fn crc32_is_the_ieee_one() {
    assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    assert_eq!(crc32(b""), 0);
}

#[test]
fn a_version_round_trips_through_its_file() {
    let v = version();
    let file = encode_map_version_file(&v).unwrap();
    assert_eq!(decode_map_version_file(&file).unwrap(), v);
    let returns: Vec<_> = v.nodes[0].returns().collect();
    assert_eq!(returns, [(-0.5, 3.0), (0.5, 12.25)]);
    let plain = MapVersion {
        datum: None,
        imported_from: None,
        ..v
    };
    let file = encode_map_version_file(&plain).unwrap();
    assert_eq!(decode_map_version_file(&file).unwrap(), plain);
}

#[test]
fn every_cut_and_every_flipped_byte_is_refused() {
    let file = encode_map_version_file(&version()).unwrap();
    for len in 0..file.len() {
        assert!(
            decode_map_version_file(&file[..len]).is_err(),
            "cut at {len} of {}",
            file.len()
        );
    }
    for i in 0..file.len() {
        let mut damaged = file.clone();
        damaged[i] ^= 0x10;
        assert!(decode_map_version_file(&damaged).is_err(), "byte {i}");
    }
    let mut damaged = file;
    let last = damaged.len() - 10;
    damaged[last] ^= 1;
    let e = decode_map_version_file(&damaged).unwrap_err();
    assert!(e.to_string().contains("damaged"), "{e}");
}

#[test]
fn another_format_or_message_is_refused_by_name() {
    let body = map_version_to_wire(&version()).encode_to_vec();
    let file = |format_version, message: &str| {
        v1::MapVersionFile {
            format_version,
            message: message.into(),
            map_version_crc32: crc32(&body),
            map_version: body.clone(),
        }
        .encode_to_vec()
    };
    let e = decode_map_version_file(&file(2, MAP_VERSION_MESSAGE)).unwrap_err();
    assert!(matches!(e, WireError::Version { found: 2, .. }), "{e:?}");
    assert!(
        e.to_string().contains("MapVersionFile.format_version"),
        "{e}"
    );
    let e = decode_map_version_file(&file(1, "levelmap.v1.Node")).unwrap_err();
    assert!(e.to_string().contains("levelmap.v1.Node"), "{e}");
    // A node message is not a version file.
    let node = crate::convert::fixtures::node().encode_to_vec();
    assert!(decode_map_version_file(&node).is_err());
}

#[test]
fn out_of_domain_fields_are_refused_by_name() {
    let says = |e: WireError, field: &str| {
        assert!(e.to_string().contains(field), "{field}: {e}");
    };
    says(refused(|m| m.fleet_id = "a/b".into()), "fleet id");
    says(refused(|m| m.number = 0), "MapVersion.number");
    says(refused(|m| m.nodes.clear()), "MapVersion.nodes");
    says(refused(|m| m.grid = None), "MapVersion.grid");
    says(refused(|m| m.nodes[1].pose = None), "VersionNode.pose");
    says(
        refused(|m| m.nodes[1].pose.as_mut().unwrap().x_m = f64::NAN),
        "Pose2D.x_m",
    );
    says(
        refused(|m| m.nodes[1].pose.as_mut().unwrap().y_m = 2e6),
        "Pose2D.y_m",
    );
    says(
        refused(|m| {
            m.nodes[0].range_m.pop();
        }),
        "VersionNode.range_m",
    );
    says(
        refused(|m| m.nodes[0].range_m[1] = -1.0),
        "VersionNode.range_m",
    );
    says(
        refused(|m| m.nodes[0].bearing_rad[2] = f32::INFINITY),
        "VersionNode.bearing_rad",
    );
    says(refused(|m| m.nodes[2].robot_id.clear()), "robot id");
    says(
        refused(|m| m.datum.as_mut().unwrap().latitude_deg = 91.0),
        "GeoDatum.latitude_deg",
    );
    says(
        refused(|m| grid(m).width = 4),
        "VersionGrid.occupancy_percent",
    );
    says(
        refused(|m| grid(m).occupancy_percent[1] = 150),
        "VersionGrid.occupancy_percent",
    );
    says(
        refused(|m| grid(m).resolution_m = 0.0),
        "VersionGrid.resolution_m",
    );
    says(
        refused(|m| grid(m).free_percent = 80),
        "VersionGrid.free_percent",
    );
    says(
        refused(|m| grid(m).occupied_percent = 101),
        "occupied_percent",
    );
}

#[test]
fn a_file_over_the_bound_is_refused_before_it_is_decoded() {
    let big = vec![0u8; MAX_MAP_VERSION_BYTES + 1];
    let e = decode_map_version_file(&big).unwrap_err();
    assert_eq!(e.reason(), "too_large");
}
