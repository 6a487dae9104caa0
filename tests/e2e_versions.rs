//! Map versions over a real mapper fed real nodes over Zenoh: a version is frozen over HTTP,
//! listed and fetched; it stays as it was while more nodes arrive; `levelmap map export`
//! saves it and `levelmap map import` takes it into a second mapper unchanged (poses, scans,
//! datum, grid); a cut or foreign-format file is refused with nothing stored; a delete's
//! number is not given again; a fleet holding `max_versions` refuses one more.

mod common;

use common::*;
use serde_json::Value;
use std::path::Path;

/// The write token (it reads too), and the read token.
const TOKEN: &str = "s3cret";
const READ: &str = "r3ad-only";

fn json(body: &[u8]) -> Value {
    serde_json::from_slice(body)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(body)))
}

fn text(body: &[u8]) -> String {
    String::from_utf8_lossy(body).into_owned()
}

const VERSIONS: &str = "/api/v1/fleets/park/versions";

/// Freezes park's map on `http`: the new version's summary.
fn freeze(http: &str) -> Value {
    let (status, body, location) = call(http, "POST", VERSIONS, TOKEN, b"");
    assert_eq!(status, 201, "{}", text(&body));
    let summary = json(&body);
    assert_eq!(location, format!("{VERSIONS}/{}", summary["version"]));
    summary
}

/// A version's file from `http`, checked 200.
fn file(http: &str, version: u64) -> Vec<u8> {
    let (status, body, _) = call(
        http,
        "GET",
        &format!("{VERSIONS}/{version}/file"),
        READ,
        b"",
    );
    assert_eq!(status, 200, "{}", text(&body));
    body
}

fn listed(http: &str) -> Vec<u64> {
    let (status, body, _) = call(http, "GET", VERSIONS, READ, b"");
    assert_eq!(status, 200, "{}", text(&body));
    json(&body)["versions"]
        .as_array()
        .expect("versions")
        .iter()
        .map(|v| v["version"].as_u64().unwrap())
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn versions_are_frozen_moved_between_mappers_and_refused_when_damaged() {
    let dir = temp_dir("versions");
    let config = mapper::MapperConfig {
        token: TOKEN.into(),
        read_token: READ.into(),
        versions: mapper::config::VersionsConfig {
            max_versions: std::num::NonZeroUsize::new(3).unwrap(),
        },
        ..Default::default()
    };
    let (a_dir, b_dir) = (dir.join("a"), dir.join("b"));
    std::fs::create_dir_all(&a_dir).unwrap();
    std::fs::create_dir_all(&b_dir).unwrap();
    let (a, session, http_a) = in_process_mapper_with(&a_dir, config.clone()).await;
    let (b, session_b, http_b) = in_process_mapper_with(&b_dir, config).await;
    let nodes = real_nodes(5);

    put_until_mapped(&session, &http_a, Some(READ), &nodes[..3]).await;
    let h = http_a.clone();
    let first = tokio::task::spawn_blocking(move || freeze_and_read(&h))
        .await
        .unwrap();
    // More nodes: a new version has them, the first does not change.
    put_until_mapped(&session, &http_a, Some(READ), &nodes).await;
    let (ha, hb, d) = (http_a.clone(), http_b.clone(), dir.clone());
    tokio::task::spawn_blocking(move || {
        let second = freeze(&ha);
        assert_eq!(
            (second["version"].as_u64(), second["nodes"].as_u64()),
            (Some(2), Some(5))
        );
        assert_eq!(
            file(&ha, 1),
            first,
            "version 1 changed after more nodes came"
        );
        export_and_import(&ha, &hb, &d, &first);
        refuse_damaged(&hb, &d, &first);
        delete_and_bound(&ha);
    })
    .await
    .unwrap();
    session.close().await.unwrap();
    session_b.close().await.unwrap();
    a.stop().await.unwrap();
    b.stop().await.unwrap();
    std::fs::remove_dir_all(&dir).ok();
}

/// Version 1 of three nodes: the write token only; listed, summarized, its file the map's
/// poses and scans. Returns its file.
fn freeze_and_read(http: &str) -> Vec<u8> {
    let (status, body, _) = call(http, "POST", VERSIONS, READ, b"");
    assert_eq!(status, 403, "{}", text(&body));
    let summary = freeze(http);
    assert_eq!(summary["version"], 1);
    assert_eq!(
        (summary["nodes"].as_u64(), summary["robots"].as_u64()),
        (Some(3), Some(1))
    );
    assert!(summary["datum"]["latitude_deg"].is_number(), "{summary}");
    assert_eq!(listed(http), [1]);
    let (status, body, _) = call(http, "GET", &format!("{VERSIONS}/1"), READ, b"");
    assert_eq!((status, json(&body)), (200, summary.clone()));
    // The answers fit the schemas the OpenAPI document gives them.
    let doc = common::openapi::OpenApiDoc::fetch_with(http, Some(READ));
    doc.check_json(&format!("{VERSIONS}/1"), &summary);
    let (_, list, _) = call(http, "GET", VERSIONS, READ, b"");
    doc.check_json(VERSIONS, &json(&list));
    let bytes = file(http, 1);
    assert_eq!(summary["file_bytes"].as_u64(), Some(bytes.len() as u64));
    let version = wire::decode_map_version_file(&bytes).expect("the file reads back");
    let graph = get_json_with(http, "/api/v1/fleets/park/graph", Some(READ)).expect("graph");
    for (node, g) in version.nodes.iter().zip(graph["nodes"].as_array().unwrap()) {
        let x = g["pose"]["x"].as_f64().unwrap();
        assert!((node.pose.x - x).abs() < 1e-9, "{node:?} {g}");
        assert_eq!(node.robot, "robot0");
        assert!(node.returns().count() > 10, "{node:?}");
    }
    let detail = get_json_with(http, "/api/v1/fleets/park/nodes/2", Some(READ)).expect("node");
    let ranges: Vec<f32> = serde_json::from_value(detail["scan"]["range_m"].clone()).unwrap();
    assert_eq!(version.nodes[2].ranges_m, ranges);
    bytes
}

/// `levelmap map export` from A; `levelmap map import` into B: the same map there.
fn export_and_import(http_a: &str, http_b: &str, dir: &Path, first: &[u8]) {
    let out = dir.join("park-v1.mapversion");
    let exported = levelmap()
        .args(["map", "export", "park", "1"])
        .arg(&out)
        .args([
            "--mapper",
            &format!("http://{http_a}"),
            "--token",
            READ,
            "--json",
        ])
        .output()
        .unwrap();
    assert!(exported.status.success(), "{}", text(&exported.stderr));
    let report = json(&exported.stdout);
    assert_eq!(
        (report["version"].as_u64(), report["nodes"].as_u64()),
        (Some(1), Some(3))
    );
    assert_eq!(std::fs::read(&out).unwrap(), first);

    let imported = levelmap()
        .args(["map", "import"])
        .arg(&out)
        .args(["--mapper", http_b, "--token", TOKEN, "--json"])
        .output()
        .unwrap();
    assert!(imported.status.success(), "{}", text(&imported.stderr));
    let summary = json(&imported.stdout);
    assert_eq!(summary["version"], 1, "{summary}");
    assert_eq!(summary["imported_from"]["fleet"], "park");
    assert_eq!(summary["imported_from"]["version"], 1);
    let original = wire::decode_map_version_file(first).unwrap();
    let copy = wire::decode_map_version_file(&file(http_b, 1)).unwrap();
    assert!(original.datum.is_some());
    assert_eq!(
        (&copy.nodes, copy.datum, &copy.grid, copy.created_ns),
        (
            &original.nodes,
            original.datum,
            &original.grid,
            original.created_ns
        )
    );
    assert_eq!(copy.imported_from.map(|o| o.number), Some(1));
}

/// A cut file and a file of format version 2: refused by the command (nothing sent) and by
/// the mapper (nothing stored), each naming the problem.
fn refuse_damaged(http_b: &str, dir: &Path, first: &[u8]) {
    let cut = dir.join("cut.mapversion");
    std::fs::write(&cut, &first[..first.len() / 2]).unwrap();
    let refused = levelmap()
        .args(["map", "import"])
        .arg(&cut)
        .args(["--mapper", http_b, "--token", TOKEN])
        .output()
        .unwrap();
    assert!(!refused.status.success());
    let why = text(&refused.stderr);
    assert!(
        why.contains("not a map version file") && why.contains("nothing sent"),
        "{why}"
    );

    let import = "/api/v1/fleets/park/versions/import";
    let (status, body, _) = call(http_b, "POST", import, TOKEN, &first[..first.len() - 3]);
    assert_eq!(status, 400, "{}", text(&body));
    assert!(text(&body).contains("nothing stored"), "{}", text(&body));
    use wire::Message;
    let mut newer = wire::v1::MapVersionFile::decode(first).unwrap();
    newer.format_version = 2;
    let (status, body, _) = call(http_b, "POST", import, TOKEN, &newer.encode_to_vec());
    assert_eq!(status, 400);
    assert!(text(&body).contains("format_version"), "{}", text(&body));
    // Refused before the body is read: a short one, so the answer is not lost in the upload.
    let (status, _, _) = call(http_b, "POST", import, READ, b"x");
    assert_eq!(status, 403);
    // The command asks first, and says why.
    let out = dir.join("park-v1.mapversion");
    let refused = levelmap()
        .args(["map", "import"])
        .arg(&out)
        .args(["--mapper", http_b, "--token", READ])
        .output()
        .unwrap();
    assert!(!refused.status.success());
    let why = text(&refused.stderr);
    assert!(
        why.contains("only reads") && why.contains("nothing sent"),
        "{why}"
    );
    assert_eq!(listed(http_b), [1]);
}

/// Delete: the write token only, then 404; numbers go on; the fourth version of a fleet
/// keeping three is refused (409), saying why.
fn delete_and_bound(http: &str) {
    let one = format!("{VERSIONS}/1");
    assert_eq!(call(http, "DELETE", &one, READ, b"").0, 403);
    assert_eq!(call(http, "DELETE", &one, TOKEN, b"").0, 204);
    let (status, body, _) = call(http, "GET", &one, READ, b"");
    assert_eq!(status, 404);
    assert!(text(&body).contains("no version 1"), "{}", text(&body));
    assert_eq!(call(http, "DELETE", &one, TOKEN, b"").0, 404);
    assert_eq!(freeze(http)["version"], 3);
    assert_eq!(freeze(http)["version"], 4);
    assert_eq!(listed(http), [2, 3, 4]);
    let (status, body, _) = call(http, "POST", VERSIONS, TOKEN, b"");
    assert_eq!(status, 409);
    assert!(text(&body).contains("keeps 3 versions"), "{}", text(&body));
    let (status, _, _) = call(http, "GET", "/api/v1/fleets/elsewhere/versions", READ, b"");
    assert_eq!(status, 404);
}
