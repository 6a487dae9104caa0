//! A fleet mapped as the worker maps it (solves taken and applied a few nodes later, their
//! points committed, a snapshot between solves), then restored from its snapshot and the
//! nodes after it, against a full replay of its nodes.

use super::*;
use crate::store::{FleetBatch, encode_edges, temp_store};
use leveling::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use leveling::{Beam, LeveledScan, TimedPose};
use slam::Pose2;
use slam::geodesy::{GeoDatum, Geodetic};
use slam::matching::synthetic::{Scene, uniform_bearings};
use std::sync::atomic::Ordering;
use wire::{Message, v1};

const S: u64 = 1_000_000_000;
const DATUM: Geodetic = Geodetic {
    latitude_deg: 52.39,
    longitude_deg: 9.71,
    height_m: 55.0,
};

/// Every node mapped: no passes over covered ground (`coverage_config` has them).
fn config(dir: &std::path::Path) -> MapperConfig {
    let mut config = coverage_config(dir);
    config.mapping.coverage.enabled = false;
    config
}

fn coverage_config(dir: &std::path::Path) -> MapperConfig {
    MapperConfig {
        store_path: dir.join("mapper.redb"),
        datum: Some(DATUM),
        ..MapperConfig::default()
    }
}

/// Node `k` of robot `r`: three robots drive circles in the synthetic park, overlapping,
/// with odometry that drifts (so closures pull); robot 2 has a GPS fix every 10th node.
fn node(r: usize, k: u64) -> v1::Node {
    let (centre, radius, step) = [
        ([0.0, -2.0], 6.0, 0.5),
        ([-4.0, 0.0], 5.0, 0.45),
        ([3.0, -3.0], 7.0, 0.55),
    ][r];
    let truth = |k: u64| {
        let a = r as f64 + k as f64 * step / radius;
        Pose2::new(
            centre[0] + radius * a.cos(),
            centre[1] + radius * a.sin(),
            a + std::f64::consts::FRAC_PI_2,
        )
    };
    // Odometry: each true step 2 % long and turned by 3 mrad.
    let mut odometry = truth(0);
    for j in 1..=k {
        let s = truth(j - 1).between(&truth(j));
        odometry = odometry.compose(&Pose2::new(s.x * 1.02, s.y, s.theta + 0.003));
    }
    let robot = format!("robot{r}");
    let stamp = (k + 1) * S + r as u64;
    let header = |seq| v1::Header::new("park", robot.clone(), seq, stamp, stamp);
    let bearings = uniform_bearings(360, -std::f64::consts::PI, std::f64::consts::PI / 180.0);
    let ranges = Scene::park().scan(&truth(k), &bearings, 40.0, 0.01, r as u64 * 100_000 + k);
    let scan = LeveledScan {
        stamp_ns: stamp,
        beams: bearings
            .iter()
            .zip(&ranges)
            .map(|(&b, &range)| Beam {
                bearing_rad: b,
                range_m: (range > 0.1 && range < 40.0).then_some(range),
                sensor_xy_m: [0.0, 0.0],
                ground_to_m: None,
            })
            .collect(),
    };
    let pose = Isometry3::from_parts(
        Translation3::new(odometry.x, odometry.y, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, odometry.theta),
    );
    let gps = (r == 2 && k.is_multiple_of(10)).then(|| {
        let t = truth(k);
        let at = GeoDatum { origin: DATUM }.enu_to_geodetic(&Vector3::new(t.x, t.y, 0.0));
        v1::GpsFix {
            header: Some(header(k)),
            latitude_deg: at.latitude_deg,
            longitude_deg: at.longitude_deg,
            altitude_m: at.height_m,
            position_covariance_m2: vec![0.04, 0.0, 0.0, 0.0, 0.04, 0.0, 0.0, 0.0, 0.25],
            status: v1::FixStatus::RtkFixed.into(),
            satellites: 14,
            antenna_offset_m: Some(v1::Vec3 {
                x: 0.0,
                y: 0.0,
                z: 0.0,
            }),
        }
    });
    v1::Node {
        header: Some(header(k)),
        node_seq: k,
        chain_id: 1,
        held_from_seq: 0,
        scan: Some(wire::leveled_scan_to_wire(
            &scan,
            Some(&Default::default()),
            header(k),
        )),
        odometry: Some(wire::odometry_to_wire(
            &TimedPose {
                stamp_ns: stamp,
                pose,
            },
            header(k),
        )),
        gps,
        ..Default::default()
    }
}

/// The three robots' first `per_robot` nodes, taken in turn.
fn nodes(per_robot: u64) -> Vec<Vec<u8>> {
    (0..per_robot)
        .flat_map(|k| (0..3).map(move |r| node(r, k).encode_to_vec()))
        .collect()
}

/// Maps `nodes` as the worker does, committing each node (and its edges) and each solve's
/// points: a solve is taken every 17th node when due and applied 5 nodes later. Writes the
/// map's snapshot after node `snapshot_after`, then takes a solve at once. The live map.
fn map_as_the_worker(
    store: &Store,
    config: &MapperConfig,
    nodes: &[Vec<u8>],
    snapshot_after: usize,
) -> FleetMap {
    // As the mapper does at start: the fleet's rows are this version's.
    store
        .set_mapping_version(&["park"], &crate::mapping::mapping_version(config))
        .unwrap();
    let mut map = crate::mapping::new_fleet(config, "park");
    let mut out: Option<(u64, slam::BackgroundSolve)> = None;
    let mut edges = 0;
    let mut arrival = 0;
    for bytes in nodes {
        let input = wire::decode_node(bytes).unwrap();
        // Over covered ground: a span, as the worker takes it.
        if map.pass(&input).is_some() {
            let span = map.take_localized(&input, true).unwrap();
            let localized = vec![span];
            store
                .commit(&[FleetBatch {
                    fleet: "park",
                    localized,
                    ..Default::default()
                }])
                .unwrap();
            continue;
        }
        map.ingest(&input).unwrap();
        let new = encode_edges(&map.graph().edges[edges..]);
        store
            .commit(&[FleetBatch {
                fleet: "park",
                nodes: vec![(arrival as u64, bytes.as_slice())],
                first_edge: edges as u64,
                edges: new,
                ..Default::default()
            }])
            .unwrap();
        edges = map.graph().edges.len();
        arrival += 1;
        let arrival = arrival - 1;
        if let Some((taken_after, _)) = &out
            && arrival as u64 >= taken_after + 5
        {
            let (taken_after, solve) = out.take().unwrap();
            apply_and_commit(store, &mut map, taken_after, solve);
        }
        if arrival == snapshot_after {
            assert!(out.is_none(), "no solve out at the snapshot");
            store
                .put_snapshot("park", &map.snapshot().unwrap())
                .unwrap();
        }
        if out.is_none() && (arrival.is_multiple_of(17) || arrival == snapshot_after) {
            out = map.take_solve().map(|s| (arrival as u64, s));
            if out.is_some() {
                assert!(map.snapshot().is_none(), "no snapshot while a solve is out");
            }
        }
    }
    // At the end, the solve out is applied, then two more: the passes' GPS fixes since the
    // last one go into the network at the first, and count at the second.
    let last = arrival as u64 - 1;
    for _ in 0..3 {
        let (taken_after, solve) = out
            .take()
            .unwrap_or_else(|| (last, map.take_solve_now().unwrap()));
        apply_and_commit(store, &mut map, taken_after, solve);
    }
    map
}

/// Runs a solve taken after arrival `taken_after` and applies it; when applied, commits its
/// point with the passes' fixes it moved into the network, as the worker does.
fn apply_and_commit(
    store: &Store,
    map: &mut FleetMap,
    taken_after: u64,
    solve: slam::BackgroundSolve,
) {
    if map.finish_solve(solve.run()).unwrap() {
        let point = map.next_solve_point(taken_after);
        store
            .commit(&[FleetBatch {
                fleet: "park",
                solved: Some(point),
                pass_fixes: &map.take_pass_fixes(),
                ..Default::default()
            }])
            .unwrap();
    }
}

#[test]
fn a_snapshot_and_the_nodes_after_it_restore_what_a_full_replay_maps() {
    let (dir, store) = temp_store("restore-tail");
    let config = config(&dir);
    let nodes = nodes(110);
    let live = map_as_the_worker(&store, &config, &nodes, 179);
    let stored = store.load_fleet("park").unwrap();
    assert!(
        stored.solve_points.len() >= 5,
        "{} solves",
        stored.solve_points.len()
    );
    let stats = live.stats();
    assert!(stats.loop_closures > 10 && stats.gps_edges > 5, "{stats:?}");

    let full = replay(&config, &stored).unwrap();
    assert_eq!(
        differences(&live, &full),
        Vec::<String>::new(),
        "the replay maps as the worker did"
    );
    let bytes = store.snapshot("park").unwrap().unwrap();
    let (restored, covered) = from_snapshot(&config, &stored, &bytes).unwrap();
    assert_eq!(covered, 180);
    // Bit for bit: poses, edges, GPS edges, counts, robots, solves.
    assert_eq!(differences(&restored, &full), Vec::<String>::new());
    assert_eq!(largest_pose_difference(&restored, &full), 0.0);

    // What the mapper does at start: the snapshot used, the store verified.
    let shared = Shared::new(String::new(), 0);
    let (fleets, covered) = restore(&config, &store, &shared).unwrap();
    assert_eq!(covered["park"], 180);
    assert_eq!(differences(&fleets["park"], &full), Vec::<String>::new());
    let check = verify_store(&config, &store).unwrap();
    assert!(check.ok, "{check:?}");
    assert_eq!(check.fleets[0].snapshot.as_ref().unwrap().covers, 180);

    // Both go on mapping the same way.
    let (mut a, mut b) = (restored, full);
    for r in 0..3 {
        let input = wire::decode_node(&node(r, 110).encode_to_vec()).unwrap();
        a.ingest(&input).unwrap();
        b.ingest(&input).unwrap();
    }
    let (sa, sb) = (a.take_solve_now().unwrap(), b.take_solve_now().unwrap());
    a.finish_solve(sa.run()).unwrap();
    b.finish_solve(sb.run()).unwrap();
    assert_eq!(differences(&a, &b), Vec::<String>::new());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn passes_over_covered_ground_restore_from_a_snapshot_as_in_a_full_replay() {
    let (scratch, store) = temp_store("restore-passes-count");
    let config = coverage_config(&scratch);
    let nodes = nodes(110);
    // How many nodes are mapped (the rest pass), then a snapshot about half-way, between
    // the harness's solves.
    let mapped = map_as_the_worker(&store, &config, &nodes, usize::MAX)
        .nodes()
        .len();
    drop(store);
    let _ = std::fs::remove_dir_all(&scratch);
    let (dir, store) = temp_store("passes");
    let half = (mapped / 2) / 17 * 17 + 9;
    let live = map_as_the_worker(&store, &config, &nodes, half);
    let stored = store.load_fleet("park").unwrap();
    assert!(
        stored.localized.len() > 3,
        "{} spans passed",
        stored.localized.len()
    );
    // Robot 2's passes brought GPS fixes, stored with the solves that took them.
    let pass_fixes: usize = stored.pass_fixes.values().map(Vec::len).sum();
    assert!(
        pass_fixes > 0 && pass_fixes == live.stats().pass_fixes,
        "{pass_fixes} stored, {:?}",
        live.stats()
    );
    let full = replay(&config, &stored).unwrap();
    assert_eq!(
        differences(&live, &full),
        Vec::<String>::new(),
        "the replay maps as the worker did"
    );
    let bytes = store.snapshot("park").unwrap().unwrap();
    let (restored, covered) = from_snapshot(&config, &stored, &bytes).unwrap();
    assert_eq!(covered, half + 1);
    assert_eq!(differences(&restored, &full), Vec::<String>::new());
    for (robot, chain) in stored.localized.iter().map(|s| (&s.robot, s.chain_id)) {
        assert_eq!(
            restored.chain_acked(robot, chain),
            full.chain_acked(robot, chain)
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Over covered ground a restart changes nothing: a robot that was passing when the mapper
/// stopped goes on passing from its last pass's map pose (stored with its span), and the
/// nodes added after the restart are at most those of the running mapper and one per robot
/// whose last node was added (the first covered node of a stretch is added, and a restart
/// does not know whether that node's place was covered).
#[test]
fn a_restarted_map_passes_where_the_running_one_does() {
    let (dir, store) = temp_store("restart-passes");
    let config = coverage_config(&dir);
    let all = nodes(110);
    let cut = 3 * 80;
    let mut running = map_as_the_worker(&store, &config, &all[..cut], usize::MAX);
    let stored = store.load_fleet("park").unwrap();
    let mut restarted = replay(&config, &stored).unwrap();
    // The robots whose last node before the stop (k = 79) was passed.
    let passing: Vec<usize> = (0..3)
        .filter(|r| {
            let robot = format!("robot{r}");
            let last_pass = stored.localized.iter().filter(|s| s.robot == robot);
            last_pass
                .filter(|s| s.passed.is_some())
                .any(|s| s.last_seq == 79)
        })
        .collect();
    assert!(!passing.is_empty(), "no robot was passing at the stop");
    // Each node after the stop, as the worker takes it: its pose when passed, else added.
    let take = |map: &mut FleetMap, input: &wire::Node| {
        let passed = map.pass(input);
        match passed {
            Some(_) => drop(map.take_localized(input, true).unwrap()),
            None => drop(map.ingest(input).unwrap()),
        }
        passed
    };
    let (mut first, mut added) = (vec![Vec::new(); 3], [0, 0]);
    for (k, bytes) in all[cut..].iter().enumerate() {
        let input = wire::decode_node(bytes).unwrap();
        let decisions = [take(&mut running, &input), take(&mut restarted, &input)];
        for (n, d) in decisions.iter().enumerate() {
            added[n] += usize::from(d.is_none());
        }
        if k < 3 {
            first[k % 3] = decisions.to_vec();
        }
    }
    for &r in &passing {
        assert!(
            first[r][0].is_some() && first[r][0] == first[r][1],
            "robot{r}'s first node after the restart: running {:?}, restarted {:?}",
            first[r][0],
            first[r][1]
        );
    }
    assert!(
        added[1] <= added[0] + (3 - passing.len()),
        "added after the stop: running {}, restarted {} ({} robots passing)",
        added[0],
        added[1],
        passing.len()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_unreadable_or_unfit_snapshot_falls_back_to_the_full_replay() {
    let (dir, store) = temp_store("fallback");
    let config = config(&dir);
    let nodes = nodes(30);
    map_as_the_worker(&store, &config, &nodes, 50);
    let stored = store.load_fleet("park").unwrap();
    let full = replay(&config, &stored).unwrap();
    let good = store.snapshot("park").unwrap().unwrap();
    let mut flipped = good.clone();
    let last = flipped.len() - 1;
    flipped[last] ^= 0x10;
    let mut other_format = good.clone();
    other_format[..4].copy_from_slice(&99u32.to_le_bytes());
    let shared = Shared::new(String::new(), 0);
    for (what, bytes) in [
        ("a flipped bit", flipped),
        ("format 99", other_format),
        ("empty", Vec::new()),
        ("garbage", vec![7; 40]),
    ] {
        store.put_snapshot("park", &bytes).unwrap();
        let (fleets, covered) = restore(&config, &store, &shared).unwrap();
        assert_eq!(covered["park"], 0, "{what}: replayed in full");
        assert_eq!(
            differences(&fleets["park"], &full),
            Vec::<String>::new(),
            "{what}"
        );
        let check = verify_store(&config, &store).unwrap();
        assert!(!check.ok, "{what}: the check fails");
        assert!(check.fleets[0].replay_error.is_none(), "{what}");
    }
    assert_eq!(shared.metrics.fleets_rebuilt.load(Ordering::Relaxed), 0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_fleet_of_other_mapping_parameters_is_rebuilt_from_its_nodes_not_quarantined() {
    let (dir, store) = temp_store("rebuilt");
    let config = config(&dir);
    let nodes = nodes(60);
    map_as_the_worker(&store, &config, &nodes, 100);
    let before = store.load_fleet("park").unwrap();
    let mut other = config.clone();
    other.mapping.idc.final_max_distance_m *= 1.5;
    other.mapping.odometry_sigma_xy_per_m *= 1.5;
    assert_ne!(
        crate::mapping::mapping_version(&other),
        crate::mapping::mapping_version(&config)
    );
    let expected = replay_unchecked(&other, &before).unwrap();
    assert!(
        edges_differ(&expected, &before).is_some(),
        "the change maps the nodes to other edges"
    );

    // What a start with the changed `[mapping]` does: rebuilt, nothing quarantined.
    let shared = Shared::new(String::new(), 0);
    let (fleets, covered) = restore(&other, &store, &shared).unwrap();
    assert!(shared.quarantined.read().unwrap().is_empty());
    assert_eq!(shared.metrics.fleets_rebuilt.load(Ordering::Relaxed), 1);
    assert_eq!(
        differences(&fleets["park"], &expected),
        Vec::<String>::new()
    );
    assert_eq!(
        covered["park"],
        before.nodes.len(),
        "a new snapshot of every node"
    );
    let after = store.load_fleet("park").unwrap();
    assert_eq!(after.nodes, before.nodes, "the record untouched");
    assert_eq!(after.solve_points, before.solve_points);
    assert_eq!(after.edges, encode_edges(&expected.graph().edges));
    assert_eq!(
        store.mapping_version("park").unwrap(),
        Some(crate::mapping::mapping_version(&other))
    );
    let check = verify_store(&other, &store).unwrap();
    assert!(check.ok && check.fleets[0].rebuild.is_none(), "{check:?}");
    let check = verify_store(&config, &store).unwrap();
    assert!(
        check.ok,
        "another version's fleet is rebuilt, not failed: {check:?}"
    );
    assert!(check.fleets[0].rebuild.is_some(), "{check:?}");

    // The next start restores the rebuilt map from its snapshot.
    let shared = Shared::new(String::new(), 0);
    let (fleets, covered) = restore(&other, &store, &shared).unwrap();
    assert_eq!(shared.metrics.fleets_rebuilt.load(Ordering::Relaxed), 0);
    assert_eq!(covered["park"], before.nodes.len());
    assert_eq!(
        differences(&fleets["park"], &expected),
        Vec::<String>::new()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn edges_that_do_not_replay_under_the_same_version_are_rebuilt_not_quarantined() {
    let (dir, store) = temp_store("undeclared");
    let mut config = config(&dir);
    config.store.snapshot_every_nodes = 0;
    let nodes = nodes(20);
    let live = map_as_the_worker(&store, &config, &nodes, usize::MAX);
    let stored = store.load_fleet("park").unwrap();
    // As if an older build of the same declared version had stored another first edge.
    let mut edge = live.graph().edges[0].clone();
    edge.measurement.x += 0.25;
    store
        .commit(&[FleetBatch {
            fleet: "park",
            edges: encode_edges(&[edge]),
            ..Default::default()
        }])
        .unwrap();
    let shared = Shared::new(String::new(), 0);
    let (fleets, _) = restore(&config, &store, &shared).unwrap();
    assert!(shared.quarantined.read().unwrap().is_empty());
    assert_eq!(shared.metrics.fleets_rebuilt.load(Ordering::Relaxed), 1);
    assert_eq!(differences(&fleets["park"], &live), Vec::<String>::new());
    assert_eq!(store.load_fleet("park").unwrap().edges, stored.edges);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_store_of_a_later_format_is_refused_with_the_reason() {
    let (dir, store) = temp_store("later");
    assert_eq!(store.format().unwrap(), crate::store::STORE_FORMAT);
    drop(store);
    let path = dir.join("mapper.redb");
    {
        let db = redb::Database::open(&path).unwrap();
        let txn = db.begin_write().unwrap();
        let meta: redb::TableDefinition<&str, u64> = redb::TableDefinition::new("store_meta");
        txn.open_table(meta).unwrap().insert("format", 99).unwrap();
        txn.commit().unwrap();
    }
    let Err(e) = Store::open(&path) else {
        panic!("a store of format 99 opened");
    };
    let e = e.to_string();
    assert!(
        e.contains("store format 99") && e.contains("later levelmap"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_kernel_keeps_its_text_form_and_reads_back_from_postcard() {
    let kernel = slam::Robust::Cauchy { c: 10.0 };
    let text = serde_json::to_string(&kernel).unwrap();
    assert_eq!(
        text, r#"{"kernel":"cauchy","c":10.0}"#,
        "the stored edges' form"
    );
    assert_eq!(serde_json::from_str::<slam::Robust>(&text).unwrap(), kernel);
    let binary = postcard::to_stdvec(&kernel).unwrap();
    assert_eq!(
        postcard::from_bytes::<slam::Robust>(&binary).unwrap(),
        kernel
    );
}
