//! Real data through the whole system: an edge service reads the public 3DTK scans of a
//! rotating 2D laser (with their pose files as odometry), levels them and publishes them; the
//! mapper maps them. Checked through HTTP only.

mod common;

use common::*;
use std::time::Duration;

#[test]
fn real_3dtk_scans_flow_from_an_edge_service_into_the_map() {
    let data = testdata::shared_data("rotating_2d_laser_3d_scans_3dtk");
    let dir = temp_dir("files-source");
    let mapper = MapperProcess::start(&dir);
    let source = format!("[source.files]\nfolder = {:?}\nperiod_s = 1.0\n", data);
    let edge = spawn_edge_with(&dir, 0, &mapper.zenoh, 0.0, &source);
    let report = edge_report(edge, Duration::from_secs(120));
    // Three scans; the second and third are metres apart from the one before.
    assert_eq!(report["nodes"], 3, "{report}");
    assert_eq!(report["outbox_pending"], 0, "{report}");
    assert_eq!(node_seqs(&mapper.http, "park", "robot0"), [0, 1, 2]);
    for node in 0..3 {
        let detail = get_json(&mapper.http, &format!("/api/v1/fleets/park/nodes/{node}"))
            .expect("node detail");
        let landmark = detail["counts"]["landmark"].as_u64().expect("counts");
        let returns = detail["scan"]["range_m"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r.as_f64().unwrap() > 0.0)
            .count();
        assert!(
            landmark > 1000 && returns > 100,
            "node {node}: {landmark} landmark points, {returns} returns"
        );
    }
    drop(mapper);
    std::fs::remove_dir_all(&dir).ok();
}
