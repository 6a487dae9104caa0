//! The HTTP API over a real mapper fed real nodes over Zenoh: every route answers in the
//! format users' tools read (JSON, TUM, g2o, PNG, PGM + YAML for map_server, GeoJSON), a
//! node's 3D cloud is served when it came with one, reading needs the read (or write) token
//! and write routes the write token.

mod common;

use common::*;

/// The write token (it reads too).
const TOKEN: &str = "s3cret";
/// The read token: every `/api` route but `/api/v1/auth` needs one of the two.
const READ: &str = "r3ad-only";

/// GET with the read token: (status, body).
fn read(http: &str, path: &str) -> Option<(u16, String)> {
    http_get_with(http, path, Some(READ)).map(|a| (a.status, a.body))
}

/// POST with an optional bearer token: the status.
fn http_post(addr: &str, path: &str, token: Option<&str>) -> u16 {
    let mut request = agent().post(format!("http://{addr}{path}"));
    if let Some(t) = token {
        request = request.header("Authorization", format!("Bearer {t}"));
    }
    request.send_empty().expect("an answer").status().as_u16()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_route_answers_in_its_format() {
    let dir = temp_dir("api");
    let config = mapper::MapperConfig {
        token: TOKEN.into(),
        read_token: READ.into(),
        ..Default::default()
    };
    let (mapper, session, http) = in_process_mapper_with(&dir, config).await;
    let mut nodes = real_nodes(3);
    // Nodes 0 and 1 come with their segmented cloud, node 2 without.
    let cloud = nodes[1].cloud.clone().expect("a cloud");
    nodes[2].cloud = None;
    put_until_mapped(&session, &http, Some(READ), &nodes).await;
    let h = http.clone();
    tokio::task::spawn_blocking(move || {
        check_routes(&h, &cloud);
        check_tokens(&h);
    })
    .await
    .unwrap();
    session.close().await.unwrap();
    mapper.stop().await.unwrap();
    std::fs::remove_dir_all(&dir).ok();
}

/// Each route of the document answers, to the read token: nothing falls through to the
/// router's own 404 (an empty body) or 405, nothing is refused. The event stream, which never
/// ends, is left out.
fn every_documented_route_is_served(http: &str, doc: &common::openapi::OpenApiDoc) {
    let ops = doc.operations();
    assert!(ops.len() >= 23, "{} operations documented", ops.len());
    for (template, method, types) in ops {
        if types.iter().any(|t| t == "text/event-stream") {
            continue;
        }
        let path = template
            .replace("{fleet}", "park")
            .replace("{robot}", "robot0")
            .replace("{node}", "0")
            .replace("{version}", "1")
            .replace("{file}", "style.css")
            .replace("{z}/{x}/{y}", "18/138142/86126.png");
        let (status, body) = match method.as_str() {
            "get" => read(http, &path).unwrap_or_else(|| panic!("GET {path}: no answer")),
            "post" => (http_post(http, &path, None), String::from("(not read)")),
            "delete" | "put" => (
                http_call(http, &method.to_uppercase(), &path, &[]).map_or(0, |a| a.status),
                String::from("(not read)"),
            ),
            other => panic!("{other} {template}: a method the test does not know"),
        };
        assert!(
            status != 405 && !(status == 404 && body.is_empty()),
            "{method} {template} is documented but not served ({status})"
        );
        assert!(
            method != "get" || status != 401,
            "GET {template} refuses the read token"
        );
    }
}

fn check_routes(http: &str, sent_cloud: &wire::v1::SegmentedCloud) {
    let base = "/api/v1/fleets/park";
    let get = |path: &str| {
        let (status, body) = read(http, path).unwrap_or_else(|| panic!("{path}: no answer"));
        assert_eq!(status, 200, "{path}: {body}");
        body
    };
    // Each JSON answer is checked against the schema its route documents.
    let doc = common::openapi::OpenApiDoc::fetch_with(http, Some(READ));
    let json = |path: &str| -> serde_json::Value {
        let value = serde_json::from_str(&get(path)).unwrap_or_else(|e| panic!("{path}: {e}"));
        doc.check_json(path, &value);
        value
    };
    every_documented_route_is_served(http, &doc);
    // The schemas are strict enough to catch a wrong answer.
    let wrong = serde_json::json!({"fleet": 3, "nodes": "many"});
    assert!(doc.violations(&format!("{base}/summary"), &wrong).len() >= 2);

    let summary = json(&format!("{base}/summary"));
    assert_eq!(summary["nodes"], 3);
    assert_eq!(summary["robots"], 1);
    let robots = json(&format!("{base}/robots"));
    assert_eq!(robots["robots"][0]["id"], "robot0");
    let pose = json(&format!("{base}/robots/robot0/pose"));
    assert!(pose["pose"]["x"].is_number(), "{pose}");
    // The same graph as columns, for the dashboard. A background solve may land between two
    // reads (the GPS fixes arrive after the nodes): read until the graph is the same on both
    // sides of the columns.
    let (graph, columns) = (0..20)
        .find_map(|_| {
            let before = json(&format!("{base}/graph?information=true"));
            let columns = json(&format!("{base}/graph?columns=true"));
            let after = json(&format!("{base}/graph?information=true"));
            if before == after {
                return Some((after, columns));
            }
            std::thread::sleep(std::time::Duration::from_millis(200));
            None
        })
        .expect("the graph settles");
    assert_eq!(graph["nodes"].as_array().unwrap().len(), 3);
    assert_eq!(graph["edges"].as_array().unwrap().len(), 2, "{graph}");
    assert!(graph["edges"][0]["information"].is_array());
    assert_eq!(columns["robots"], serde_json::json!(["robot0"]));
    assert_eq!(columns["nodes"]["node_seq"], serde_json::json!([0, 1, 2]));
    for (i, n) in graph["nodes"].as_array().unwrap().iter().enumerate() {
        let x = columns["nodes"]["x"][i].as_f64().unwrap();
        assert!(
            (x - n["pose"]["x"].as_f64().unwrap()).abs() <= 5e-4,
            "{columns}"
        );
    }
    assert_eq!(columns["edges"]["from"], serde_json::json!([0, 1]));
    let kind = columns["edges"]["kind"][0].as_u64().unwrap() as usize;
    assert_eq!(columns["kinds"][kind], graph["edges"][0]["kind"]);
    // Node uncertainty: symmetric 3 × 3 with positive variances (null for the gauge node).
    let covs = json(&format!("{base}/covariances?nodes=2,1,0"));
    assert_eq!(covs["nodes"], serde_json::json!([2, 1, 0]));
    let c = &covs["covariance"][0];
    for r in 0..3 {
        assert!(c[r][r].as_f64().unwrap() > 0.0, "{covs}");
        for k in 0..3 {
            assert_eq!(c[r][k].as_f64(), c[k][r].as_f64(), "{covs}");
        }
    }
    assert_eq!(
        read(http, &format!("{base}/covariances?nodes=7"))
            .unwrap()
            .0,
        404
    );
    assert_eq!(
        read(http, &format!("{base}/covariances?nodes=x"))
            .unwrap()
            .0,
        400
    );
    let node = json(&format!("{base}/nodes/1"));
    assert_eq!(node["node_seq"], 1);
    assert!(!node["scan"]["range_m"].as_array().unwrap().is_empty());
    assert_eq!(read(http, &format!("{base}/nodes/99")).unwrap().0, 404);
    check_clouds(http, &node, sent_cloud);
    assert_eq!(read(http, "/api/v1/fleets/nowhere/summary").unwrap().0, 404);

    // TUM: a comment line, then `t x y z qx qy qz qw` per node.
    let tum = get(&format!("{base}/robots/robot0/trajectory.tum"));
    let rows: Vec<&str> = tum.lines().filter(|l| !l.starts_with('#')).collect();
    assert_eq!(rows.len(), 3);
    assert!(rows.iter().all(|r| r.split_whitespace().count() == 8));
    // g2o: three vertices, two edges.
    let g2o = get(&format!("{base}/graph.g2o"));
    assert_eq!(
        g2o.lines().filter(|l| l.starts_with("VERTEX_SE2")).count(),
        3
    );
    assert_eq!(g2o.lines().filter(|l| l.starts_with("EDGE_SE2")).count(), 2);
    // The grid as map_server reads it: PGM (P5) and a YAML naming it.
    let yaml = get(&format!("{base}/map.yaml"));
    assert!(
        yaml.contains("image: map.pgm") && yaml.contains("resolution:"),
        "{yaml}"
    );
    let pgm = read(http, &format!("{base}/map.pgm")).unwrap();
    assert_eq!(pgm.0, 200);
    assert!(pgm.1.starts_with("P5"), "PGM header");
    let png = read(http, &format!("{base}/map.png")).unwrap();
    assert_eq!(png.0, 200);
    assert!(png.1.as_bytes().starts_with(b"\x89PNG") || png.1.contains("PNG"));
    // Where the PNG lies: a positive cell size and a grid of cells.
    let meta = json(&format!("{base}/map.json"));
    assert!(meta["resolution_m"].as_f64().unwrap() > 0.0, "{meta}");
    assert!(meta["width"].as_u64().unwrap() > 0 && meta["origin_m"].is_array());
    assert_eq!(meta["nodes"], 3);
    // A part of the map, and a cap on cells that coarsens instead of refusing.
    let res = meta["resolution_m"].as_f64().unwrap();
    let (x0, y0) = (
        meta["origin_m"][0].as_f64().unwrap(),
        meta["origin_m"][1].as_f64().unwrap(),
    );
    let part = json(&format!(
        "{base}/map.json?bbox={x0},{y0},{},{}",
        x0 + 5.0,
        y0 + 3.0
    ));
    assert_eq!(part["resolution_m"].as_f64().unwrap(), res, "{part}");
    // 5 m × 3 m of 0.1 m cells, and one cell of margin on each side.
    let (w, h) = (
        part["width"].as_u64().unwrap(),
        part["height"].as_u64().unwrap(),
    );
    assert!(
        w <= 53
            && h <= 33
            && w * h < meta["width"].as_u64().unwrap() * meta["height"].as_u64().unwrap(),
        "{part}"
    );
    let coarse = json(&format!("{base}/map.json?max_cells=10000"));
    let cells = coarse["width"].as_u64().unwrap() * coarse["height"].as_u64().unwrap();
    assert!(
        cells <= 10_000 && coarse["resolution_m"].as_f64().unwrap() > res,
        "{coarse}"
    );
    assert_eq!(
        read(http, &format!("{base}/map.png?bbox=1,2,3")).unwrap().0,
        400
    );
    // The dashboard at / and its modules under /web/.
    let page = read(http, "/").unwrap();
    assert_eq!(page.0, 200);
    assert!(page.1.contains("/web/app.js"), "the page loads its module");
    assert_eq!(read(http, "/web/app.js").unwrap().0, 200);
    assert_eq!(read(http, "/web/cloud.js").unwrap().0, 200);
    assert_eq!(read(http, "/web/nope.js").unwrap().0, 404);
    // GeoJSON in WGS84 near the simulated park's datum (lon 9.71, lat 52.39).
    let geo = json(&format!("{base}/map.geojson"));
    assert_eq!(geo["type"], "FeatureCollection");
    let c = &geo["features"][0]["geometry"]["coordinates"];
    assert!((c[0].as_f64().unwrap() - 9.71).abs() < 0.01, "{c}");
    assert!((c[1].as_f64().unwrap() - 52.39).abs() < 0.01, "{c}");
    // No base map unless the config names one: the page then asks no other server.
    assert!(json("/api/v1/dashboard")["base_map"].is_null());
    // map_server's scale mode: the PNG carries the evidence, the YAML says so.
    let scale_yaml = get(&format!("{base}/map.yaml?mode=scale"));
    assert!(
        scale_yaml.contains("image: map.png\n") && scale_yaml.contains("mode: scale\n"),
        "{scale_yaml}"
    );
    assert!(
        scale_yaml.contains("occupied_thresh: 0.65\nfree_thresh: 0.35\n"),
        "{scale_yaml}"
    );
    assert_eq!(
        read(http, &format!("{base}/map.png?mode=scale")).unwrap().0,
        200
    );
    assert_eq!(
        read(http, &format!("{base}/map.png?mode=raw")).unwrap().0,
        400
    );
    // The grid on the Earth (tests/e2e_geo.rs reads both with rasterio): a little-endian
    // TIFF, and web tiles, transparent away from the map, refused past the scheme.
    let tif = read(http, &format!("{base}/map.tif")).unwrap();
    assert_eq!(tif.0, 200, "{}", tif.1);
    assert!(tif.1.starts_with("II*\0"), "a TIFF");
    for (tile, status) in [
        ("25/0/0.png", 400),
        ("3/8/0", 400),
        ("3/0/x.png", 400),
        ("18/0/0.png", 200),
    ] {
        let answer = read(http, &format!("{base}/tiles/{tile}")).unwrap();
        assert_eq!(answer.0, status, "tiles/{tile}: {}", answer.1);
    }
    // OpenAPI names the routes; metrics are Prometheus text.
    let openapi = json("/api/v1/openapi.json");
    assert!(openapi["paths"]["/api/v1/fleets/{fleet}/summary"].is_object());
    assert!(openapi["paths"]["/api/v1/fleets/{fleet}/nodes/{node}/cloud"].is_object());
    assert!(get("/metrics").contains("levelmap_nodes_accepted_total 3"));
}

/// Reading needs the read or the write token (401 with `WWW-Authenticate: Bearer` without);
/// writing needs the write token; the probes, the metrics, the page and the token check are
/// open.
fn check_tokens(http: &str) {
    let summary = "/api/v1/fleets/park/summary";
    for token in [None, Some("wrong"), Some(&READ[1..])] {
        let a = http_get_with(http, summary, token).unwrap();
        assert_eq!(a.status, 401, "{token:?}");
        assert_eq!(
            a.header("www-authenticate"),
            Some("Bearer realm=\"levelmap\"")
        );
    }
    for token in [READ, TOKEN] {
        assert_eq!(
            http_get_with(http, summary, Some(token)).unwrap().status,
            200
        );
    }
    for open in ["/healthz", "/metrics", "/", "/web/app.js", "/api/v1/auth"] {
        assert_eq!(http_get(http, open).unwrap().0, 200, "{open}");
    }
    let optimize = "/api/v1/fleets/park/optimize";
    assert_eq!(http_post(http, optimize, None), 401);
    assert_eq!(http_post(http, optimize, Some("wrong")), 401);
    assert_eq!(http_post(http, optimize, Some(READ)), 403);
    assert_eq!(http_post(http, optimize, Some(TOKEN)), 200);
    // A page finds out what it needs without meeting a 401.
    let auth = get_json(http, "/api/v1/auth").unwrap();
    assert_eq!(
        (
            &auth["read_required"],
            &auth["read"],
            &auth["write_routes"],
            &auth["authorized"]
        ),
        (&true.into(), &false.into(), &true.into(), &false.into()),
        "{auth}"
    );
    let auth = get_json_with(http, "/api/v1/auth", Some(READ)).unwrap();
    assert_eq!(
        (&auth["read"], &auth["authorized"]),
        (&true.into(), &false.into())
    );
}

/// Node 1's cloud as sent (to the centimetre, in the leveled frame, classes 1..3); node 2 came
/// without one: 404 with the reason, and its detail says so.
fn check_clouds(http: &str, node1: &serde_json::Value, sent: &wire::v1::SegmentedCloud) {
    let base = "/api/v1/fleets/park/nodes";
    assert_eq!(node1["cloud"], true, "{node1}");
    let (status, body) = read(http, &format!("{base}/1/cloud")).unwrap();
    assert_eq!(status, 200, "{body}");
    let c: serde_json::Value = serde_json::from_str(&body).unwrap();
    assert_eq!(
        (c["id"].as_u64(), c["frame"].as_str()),
        (Some(1), Some("leveled"))
    );
    let points = c["points"].as_array().unwrap();
    let classes = c["classes"].as_array().unwrap();
    let kept = c["kept"].as_u64().unwrap() as usize;
    assert!(kept > 0 && kept <= 6000, "{kept}");
    assert_eq!((points.len(), classes.len()), (3 * kept, kept));
    for (got, sent) in points.iter().zip(&sent.xyz_cm) {
        assert_eq!(got.as_f64().unwrap(), f64::from(*sent) / 100.0);
    }
    let sent_classes: Vec<u64> = sent.classes.iter().map(|&b| b.into()).collect();
    let classes: Vec<u64> = classes.iter().map(|v| v.as_u64().unwrap()).collect();
    assert_eq!(classes, sent_classes);
    let counts = &c["counts"];
    for (name, code) in [("ground", 1), ("landmark", 2), ("overhang", 3)] {
        let n = counts[name].as_u64().unwrap();
        assert!(n > 0, "{name}: {counts}");
        assert_eq!(n as usize, classes.iter().filter(|&&k| k == code).count());
    }
    let scan = &node1["counts"];
    let valid = ["ground", "landmark", "overhang"].map(|k| scan[k].as_u64().unwrap());
    assert_eq!(c["source_points"].as_u64(), Some(valid.iter().sum()));
    for (k, n) in ["ground", "landmark", "overhang"].iter().zip(valid) {
        assert_eq!(c["source_counts"][k].as_u64(), Some(n), "{k}");
    }
    assert_eq!(
        (c["max_points"].as_u64(), c["voxel_m"].as_f64()),
        (Some(6000), Some(0.1))
    );

    let node2 = get_json_with(http, &format!("{base}/2"), Some(READ)).unwrap();
    assert_eq!(node2["cloud"], false);
    let (status, body) = read(http, &format!("{base}/2/cloud")).unwrap();
    assert_eq!(status, 404);
    assert!(
        body.contains("node 2") && body.contains("no 3D cloud"),
        "{body}"
    );
    assert_eq!(read(http, &format!("{base}/99/cloud")).unwrap().0, 404);
}
