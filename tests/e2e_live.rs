//! A robot's live feed (`GET …/robots/{robot}/live`) from outside: a simulated robot drives
//! in real time; its feed comes over server-sent events and over a WebSocket with the map
//! pose at every odometry sample and its live scans, and a subscriber that stops reading is
//! costs the mapper no memory while the others go on at full rate (that it skips to the newest
//! sample rather than queue is `api/live.rs`'s unit test).

mod common;

use common::sse::Sse;
use common::*;
use serde_json::Value;
use std::io::Read;
use std::time::{Duration, Instant};

fn stamps(samples: &[Value]) -> Vec<u64> {
    samples
        .iter()
        .map(|s| s["stamp_ns"].as_u64().unwrap())
        .collect()
}

/// Every sample of one robot, its pose on the map once it has a node, stamps increasing,
/// and at least one live scan with its beams.
fn check_feed(samples: &[Value], what: &str) {
    assert!(
        samples.len() >= 20,
        "{what}: {} samples in 3 s",
        samples.len()
    );
    let t = stamps(samples);
    assert!(t.windows(2).all(|w| w[0] < w[1]), "{what}: stamps {t:?}");
    for s in samples {
        assert_eq!(
            (s["type"].as_str(), s["robot"].as_str()),
            (Some("live"), Some("robot0"))
        );
        assert!(s["pose"]["x"].is_f64(), "{what}: {s}");
        assert!(s["speed_m_s"].as_f64().unwrap() >= 0.0);
        assert!(s["correction_age_ms"].as_f64().unwrap() >= 0.0);
    }
    let scans: Vec<&Value> = samples.iter().filter(|s| s.get("scan").is_some()).collect();
    assert!(!scans.is_empty(), "{what}: no live scan in 3 s");
    for s in &scans {
        let scan = &s["scan"];
        let (b, r) = (
            scan["bearing_rad"].as_array().unwrap(),
            scan["range_m"].as_array().unwrap(),
        );
        assert!(
            b.len() > 100 && b.len() == r.len(),
            "{what}: {} beams",
            b.len()
        );
        assert!(scan["origin_in_map"]["x"].is_f64(), "{what}: {scan}");
    }
    let seqs: Vec<u64> = scans
        .iter()
        .map(|s| s["scan"]["seq"].as_u64().unwrap())
        .collect();
    assert!(
        seqs.windows(2).all(|w| w[0] < w[1]),
        "{what}: a scan sent twice: {seqs:?}"
    );
}

/// A grayscale PNG's width, height and pixels (top row first).
fn decode_png(bytes: &[u8]) -> (usize, usize, Vec<u8>) {
    let mut reader = png::Decoder::new(std::io::Cursor::new(bytes))
        .read_info()
        .expect("PNG");
    let mut pixels = vec![0; reader.output_buffer_size().expect("size")];
    let info = reader.next_frame(&mut pixels).expect("a frame");
    pixels.truncate(info.buffer_size());
    (info.width as usize, info.height as usize, pixels)
}

/// A PNG answer with its `Levelmap-Grid` placement and `Levelmap-Tiles` counts.
fn grid_png(http: &str, path: &str) -> (Value, Value, (usize, usize, Vec<u8>)) {
    let mut answer = agent()
        .get(format!("http://{http}{path}"))
        .call()
        .expect(path);
    assert_eq!(answer.status(), 200, "{path}");
    let header = |name: &str| -> Value {
        answer.headers().get(name).map_or(Value::Null, |v| {
            serde_json::from_str(v.to_str().unwrap()).unwrap()
        })
    };
    let (placement, tiles) = (header("levelmap-grid"), header("levelmap-tiles"));
    let mut bytes = Vec::new();
    answer
        .body_mut()
        .as_reader()
        .read_to_end(&mut bytes)
        .unwrap();
    (placement, tiles, decode_png(&bytes))
}

/// Once the map is still: the window around the robot, made from tiles and then served
/// from them, is cell for cell the whole map's grid over the same square.
fn window_is_the_map_around_the_robot(http: &str) {
    let updated = || get_json(http, "/api/v1/fleets/park/summary").unwrap()["updated_ns"].clone();
    let mut last = updated();
    loop {
        std::thread::sleep(Duration::from_millis(1500));
        let now = updated();
        if now == last {
            break;
        }
        last = now;
    }
    let path = "/api/v1/fleets/park/robots/robot0/map.png?radius_m=20&resolution_m=0.1";
    let (placement, cold, (w, h, window)) = grid_png(http, path);
    assert!(cold["made"].as_u64().unwrap() >= 1, "{cold}");
    let started = Instant::now();
    let (_, warm, (_, _, again)) = grid_png(http, path);
    println!(
        "window 40 m at 0.1 m: cold {cold}, warm {warm} in {:?}",
        started.elapsed()
    );
    assert_eq!(
        (warm["made"].as_u64(), warm["stale"].as_u64()),
        (Some(0), Some(0)),
        "{warm}"
    );
    assert_eq!(window, again);
    assert_eq!((w, h), (400, 400));
    let [x0, y0] = [
        placement["origin_m"][0].as_f64().unwrap(),
        placement["origin_m"][1].as_f64().unwrap(),
    ];
    let bbox = format!("{x0},{y0},{},{}", x0 + 40.0, y0 + 40.0);
    let (whole_at, _, (ww, wh, whole)) = grid_png(
        http,
        &format!("/api/v1/fleets/park/map.png?resolution_m=0.1&bbox={bbox}"),
    );
    // Both grids on the same lattice: the window's cell (col, row) is the whole grid's
    // (col + dx, row + dy), rows counted from the south.
    let dx = ((x0 - whole_at["origin_m"][0].as_f64().unwrap()) / 0.1).round() as i64;
    let dy = ((y0 - whole_at["origin_m"][1].as_f64().unwrap()) / 0.1).round() as i64;
    let (mut same, mut known) = (0, 0);
    for row in 0..h as i64 {
        for col in 0..w as i64 {
            let (wc, wr) = (col + dx, row + dy);
            let pixel = window[(h - 1 - row as usize) * w + col as usize];
            let expected = if (0..ww as i64).contains(&wc) && (0..wh as i64).contains(&wr) {
                whole[(wh - 1 - wr as usize) * ww + wc as usize]
            } else {
                205
            };
            same += usize::from(pixel == expected);
            known += usize::from(pixel != 205);
        }
    }
    assert_eq!(same, w * h, "{} of {} cells differ", w * h - same, w * h);
    assert!(known > 1000, "only {known} known cells around the robot");

    // The same window in map_server's scale mode (the dashboard's colours): grey and alpha,
    // free cells pale, occupied dark, never-seen transparent.
    let (_, _, (sw, sh, scale)) = grid_png(http, &format!("{path}&mode=scale"));
    assert_eq!((sw, sh, scale.len()), (w, h, 2 * w * h));
    for (k, &trinary) in window.iter().enumerate() {
        let (grey, alpha) = (scale[2 * k], scale[2 * k + 1]);
        match trinary {
            254 => assert!(alpha == 255 && grey >= 165, "free cell {k}: {grey}/{alpha}"),
            0 => assert!(
                alpha == 255 && grey <= 90,
                "occupied cell {k}: {grey}/{alpha}"
            ),
            _ => assert!(alpha == 0 || (90..165).contains(&grey), "unknown cell {k}"),
        }
    }
}

fn robot_has_a_node(http: &str) -> bool {
    get_json(http, "/api/v1/fleets/park/robots")
        .is_some_and(|r| r["robots"][0]["nodes"].as_u64().unwrap_or(0) >= 2)
}

#[test]
fn a_robots_live_feed_follows_it_over_sse_and_websocket() {
    let dir = temp_dir("live");
    let mapper = MapperProcess::start(&dir);
    assert_eq!(
        http_get(&mapper.http, "/api/v1/fleets/park/robots/robot0/live").map(|a| a.0),
        Some(404),
        "no feed before the robot's odometry"
    );
    let edge = spawn_edge(&dir, 0, &mapper.zenoh, 40.0, 1.0);
    assert!(
        wait_for(Duration::from_secs(30), || robot_has_a_node(&mapper.http)
            .then_some(()))
        .is_some()
    );

    let mut sse = Sse::open(&mapper.http, "/api/v1/fleets/park/robots/robot0/live");
    check_feed(&sse.during(Duration::from_secs(3)), "sse");
    drop(sse);

    let url = format!("ws://{}/api/v1/fleets/park/robots/robot0/live", mapper.http);
    let (mut socket, _) = tungstenite::connect(url).expect("the WebSocket opens");
    let until = Instant::now() + Duration::from_secs(3);
    let mut samples = Vec::new();
    while Instant::now() < until {
        match socket.read().expect("a message") {
            tungstenite::Message::Text(text) => samples.push(serde_json::from_str(&text).unwrap()),
            tungstenite::Message::Ping(_) | tungstenite::Message::Pong(_) => {}
            other => panic!("{other:?}"),
        }
    }
    check_feed(&samples, "websocket");
    socket.close(None).ok();

    let mut edge = edge;
    edge.kill().ok();
    edge.wait().ok();
    window_is_the_map_around_the_robot(&mapper.http);
    drop(mapper);
    std::fs::remove_dir_all(&dir).ok();
}

/// A WebSocket to the feed over a socket whose receive buffer is small (4 KiB), so that a
/// subscriber that does not read soon holds the server's writes.
fn small_buffer_socket(http: &str, path: &str) -> tungstenite::WebSocket<std::net::TcpStream> {
    let addr: std::net::SocketAddr = http.parse().unwrap();
    let socket = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None).unwrap();
    socket.set_recv_buffer_size(4096).unwrap();
    socket.connect(&addr.into()).expect("connects");
    let stream: std::net::TcpStream = socket.into();
    let (ws, _) = tungstenite::client(format!("ws://{http}{path}"), stream).expect("upgrades");
    ws
}

/// A process's resident memory (KiB).
fn rss_kib(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).expect("/proc");
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmRSS")
}

fn read_text(ws: &mut tungstenite::WebSocket<std::net::TcpStream>) -> Value {
    loop {
        if let tungstenite::Message::Text(text) = ws.read().expect("a message") {
            return serde_json::from_str(&text).unwrap();
        }
    }
}

#[test]
fn a_subscriber_that_stops_reading_costs_no_memory_and_no_one_else_a_sample() {
    let dir = temp_dir("live-slow");
    let mapper = MapperProcess::start(&dir);
    // 50 odometry samples and 10 live scans a second: far more than socket buffers hold in 10 s.
    let env = [
        ("LEVELMAP_ODOMETRY_RATE_HZ", "50"),
        ("LEVELMAP_LIVE_SCAN_RATE_HZ", "10"),
    ];
    let edge = spawn_edge_env(&dir, 0, &mapper.zenoh, (60.0, 1.0), &env);
    assert!(
        wait_for(Duration::from_secs(30), || robot_has_a_node(&mapper.http)
            .then_some(()))
        .is_some()
    );
    let path = "/api/v1/fleets/park/robots/robot0/live";
    let mut slow = small_buffer_socket(&mapper.http, path);
    let first = read_text(&mut slow);
    let mapper_pid = mapper.pid();
    let rss_before = rss_kib(mapper_pid);
    // The slow subscriber reads nothing for 10 s while another one reads everything.
    let mut other = Sse::open(&mapper.http, path);
    let meanwhile = other.during(Duration::from_secs(10));
    assert!(
        meanwhile.len() >= 400,
        "the other subscriber got {} samples in 10 s",
        meanwhile.len()
    );
    let newest = *stamps(&meanwhile).last().unwrap();
    // What the slow one reads now: what the buffers held, then the newest sample.
    let mut after = vec![first];
    while stamps(&after).last().unwrap() + 500_000_000 < newest {
        after.push(read_text(&mut slow));
    }
    let rss_after = rss_kib(mapper_pid);
    println!(
        "slow subscriber: {} samples read after the pause to catch up (the other got {} in \
         the 10 s); the mapper's resident memory {rss_before} -> {rss_after} KiB",
        after.len(),
        meanwhile.len(),
    );
    // The server keeps the newest sample per robot, not one queue per subscriber: what the
    // slow one had to read is what the sockets' buffers held (the kernel's bound).
    assert!(
        rss_after < rss_before + 8 * 1024,
        "the mapper grew from {rss_before} to {rss_after} KiB"
    );
    let mut edge = edge;
    edge.kill().ok();
    edge.wait().ok();
    drop(mapper);
    std::fs::remove_dir_all(&dir).ok();
}
