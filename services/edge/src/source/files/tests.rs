//! The files source on the public data (../shared/data): a missing folder fails, never skips.

use super::*;
use testdata::shared_data as data;

const EPOCH_NS: u64 = 1_000_000_000_000;

/// KITTI odometry sequence 00's published `calib.txt` `Tr:` (Velodyne → cam0), written to a
/// scratch file (the data folder's copy was typed in and has no download source).
fn kitti_00_calib() -> PathBuf {
    let path = std::env::temp_dir().join(format!("edge-calib-{}.txt", std::process::id()));
    let tr = "Tr: 4.276802385584e-04 -9.999672484946e-01 -8.084491683471e-03 -1.198459927713e-02 \
              -7.210626507497e-03 8.081198471645e-03 -9.999413164504e-01 -5.403984729748e-02 \
              9.999738645903e-01 4.859485810390e-04 -7.206933692422e-03 -2.921968648686e-01\n";
    std::fs::write(&path, tr).unwrap();
    path
}

/// Every (odometry, scan) pair of a source.
fn drain(source: &mut FilesSource) -> Vec<(TimedPose, SensorScan)> {
    let mut out = Vec::new();
    while let Some(event) = source.next_event() {
        let SourceEvent::Odometry(pose) = event else {
            panic!("a scan before its odometry")
        };
        let Some(SourceEvent::Scan(scan)) = source.next_event() else {
            panic!("odometry without its scan")
        };
        out.push((pose, *scan));
    }
    out
}

#[test]
fn kitti_scans_take_their_numbered_poses_and_times() {
    let gt = data("kitti_odometry_gt_trajectories");
    let config = FilesSourceConfig {
        folder: data("kitti_velodyne/patchwork-plusplus"),
        poses: Some(gt.join("KITTI_00_gt.txt")),
        times: Some(gt.join("KITTI_00_gt_times.txt")),
        calib: Some(kitti_00_calib()),
        ..FilesSourceConfig::default()
    };
    let scans = drain(&mut FilesSource::new(&config, EPOCH_NS).unwrap());
    assert_eq!(scans.len(), 6);
    // KITTI 00: about 0.86 m forward per frame, 0.1037 s apart; in the Velodyne's frame
    // forward is +x and the height stays put.
    let (pose, scan) = &scans[1];
    assert_eq!(pose.stamp_ns, EPOCH_NS + 103_735_900);
    assert!(scan.raw.columns.iter().all(|c| c.stamp_ns == pose.stamp_ns));
    let t = pose.pose.translation.vector;
    assert!(
        (t.x - 0.859).abs() < 0.01 && t.y.abs() < 0.05 && t.z.abs() < 0.05,
        "{t}"
    );
    let t5 = scans[5].0.pose.translation.vector;
    assert!((t5.x - 5.0 * 0.859).abs() < 0.05, "{t5}");
}

#[test]
fn an_ouster_capture_gives_its_frames_with_column_times_and_the_poses_file() {
    let dir = data("ouster_organized_scans");
    let config = FilesSourceConfig {
        pcap: Some(dir.join("OS-1-128_v2.3.0_1024x10_lb_n3.pcap")),
        ouster_meta: Some(dir.join("OS-1-128_v2.3.0_1024x10.json")),
        poses: Some(dir.join("OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt")),
        ..FilesSourceConfig::default()
    };
    let scans = drain(&mut FilesSource::new(&config, EPOCH_NS).unwrap());
    assert_eq!(scans.len(), 3);
    assert_eq!(scans[0].0.stamp_ns, EPOCH_NS);
    for (i, (pose, scan)) in scans.iter().enumerate() {
        // A rotation at 10 Hz: frames 100 ms apart, columns spread over it.
        let gap = pose.stamp_ns - EPOCH_NS;
        assert!(gap.abs_diff(i as u64 * 100_000_000) < 2_000_000, "{gap}");
        assert_eq!(scan.raw.start_stamp_ns(), pose.stamp_ns);
        let span = scan.raw.columns.last().unwrap().stamp_ns - pose.stamp_ns;
        assert!((90_000_000..110_000_000).contains(&span), "{span}");
    }
    let x = scans[2].0.pose.translation.vector.x;
    assert!((x - 0.497_825_532).abs() < 1e-6, "{x}");
}

#[test]
fn a_capture_without_its_metadata_is_refused_by_name() {
    let config = FilesSourceConfig {
        pcap: Some("capture.pcap".into()),
        ..FilesSourceConfig::default()
    };
    let e = FilesSource::new(&config, 0).err().unwrap().to_string();
    assert!(
        e.starts_with("capture.pcap: [source.files] pcap needs ouster_meta"),
        "{e}"
    );
    let config = FilesSourceConfig {
        folder: data("kitti_velodyne/patchwork-plusplus"),
        poses: Some(kitti_00_calib()),
        ..FilesSourceConfig::default()
    };
    let e = FilesSource::new(&config, 0).err().unwrap().to_string();
    assert!(
        e.contains("edge-calib-") && e.contains("txt: line 1"),
        "{e}"
    );
}
