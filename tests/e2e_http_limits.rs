//! The HTTP API's limits on a real mapper fed real nodes over Zenoh: heavy requests over the
//! limit and heavy work over its time are answered 503 with `Retry-After` (and the work of a
//! timed-out request keeps its place until it ends); event streams over their cap are
//! refused and a closed one frees its place; CORS answers the listed origins only.

mod common;

use common::*;
use mapper::MapperConfig;
use mapper::config::{CorsOrigin, HttpConfig};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::num::{NonZeroU64, NonZeroUsize};
use std::sync::{Arc, Barrier};
use std::time::{Duration, Instant};

const READ: &str = "r-token";

/// A grid of 2²⁴ cells (the server's cap) of the three nodes' scans: hundreds of ms of work.
const BIG_GRID: &str = "/api/v1/fleets/park/map.png?resolution_m=0.01&max_cells=16777216";

/// A mapper reading with [`READ`], its `[http]` as given, with three real nodes in its map.
async fn mapper_with_map(
    name: &str,
    http: HttpConfig,
) -> (mapper::Running, zenoh::Session, String, std::path::PathBuf) {
    let dir = temp_dir(name);
    let config = MapperConfig {
        read_token: READ.into(),
        http,
        ..MapperConfig::default()
    };
    let (mapper, session, addr) = in_process_mapper_with(&dir, config).await;
    put_until_mapped(&session, &addr, Some(READ), &real_nodes(3)).await;
    (mapper, session, addr, dir)
}

async fn stop(mapper: mapper::Running, session: zenoh::Session, dir: std::path::PathBuf) {
    session.close().await.unwrap();
    mapper.stop().await.unwrap();
    std::fs::remove_dir_all(&dir).ok();
}

fn limits(heavy: usize, timeout_ms: u64, streams: usize) -> HttpConfig {
    HttpConfig {
        heavy_requests: NonZeroUsize::new(heavy).unwrap(),
        heavy_timeout_ms: NonZeroU64::new(timeout_ms).unwrap(),
        event_streams: NonZeroUsize::new(streams).unwrap(),
        ..HttpConfig::default()
    }
}

/// A refusal by a limit: 503, `Retry-After: 1`, a body that says which.
fn refused(a: &Answer, says: &str) -> bool {
    a.status == 503 && a.header("retry-after") == Some("1") && a.body.contains(says)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn heavy_requests_over_the_limit_are_answered_503_at_once() {
    // Heavy work is waited for 8 s at most: every request is answered within the client's
    // 10 s, however slow the machine.
    let (mapper, session, http, dir) = mapper_with_map("limit-heavy", limits(1, 8_000, 64)).await;
    let h = http.clone();
    let answers = tokio::task::spawn_blocking(move || {
        // Eight at once to one slot: all start together, none waits for another's answer.
        let start = Arc::new(Barrier::new(8));
        let threads: Vec<_> = (0..8)
            .map(|_| {
                let (h, start) = (h.clone(), start.clone());
                std::thread::spawn(move || {
                    start.wait();
                    let t = Instant::now();
                    let a = http_get_with(&h, BIG_GRID, Some(READ)).expect("an answer");
                    (a, t.elapsed())
                })
            })
            .collect();
        threads
            .into_iter()
            .map(|t| t.join().unwrap())
            .collect::<Vec<_>>()
    })
    .await
    .unwrap();
    for (a, took) in &answers {
        println!("{} in {:.0} ms", a.status, took.as_secs_f64() * 1e3);
    }
    let ok = answers.iter().filter(|(a, _)| a.status == 200).count();
    let busy = answers.iter().filter(|(a, _)| refused(a, "busy")).count();
    let late = answers
        .iter()
        .filter(|(a, _)| refused(a, "not done"))
        .count();
    // Every request answered (expect: none timed out): the one in the slot with the grid (or
    // a 503 if it took over 8 s), the others refused at once rather than queued.
    assert_eq!(ok + busy + late, 8, "every answer a grid or a refusal");
    assert!(busy >= 1, "{ok} grids, {busy} refused busy, {late} late");
    let metrics = http_get(&http, "/metrics").unwrap().1;
    assert_eq!(
        metric(&metrics, "levelmap_http_refused_total{reason=\"busy\"}"),
        busy as u64
    );
    stop(mapper, session, dir).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_timed_out_request_is_answered_503_and_its_work_keeps_its_slot() {
    let (mapper, session, http, dir) = mapper_with_map("limit-timeout", limits(1, 1, 64)).await;
    let h = http.clone();
    tokio::task::spawn_blocking(move || {
        let late = http_get_with(&h, BIG_GRID, Some(READ)).unwrap();
        assert!(
            refused(&late, "not done within 1 ms"),
            "{}: {}",
            late.status,
            late.body
        );
        // The grid is still being made: its slot is taken, the next request is refused.
        let small = "/api/v1/fleets/park/map.json?max_cells=100";
        let next = http_get_with(&h, small, Some(READ)).unwrap();
        assert!(refused(&next, "busy"), "{}: {}", next.status, next.body);
        // Once that work ends, the slot is free again: answers are no longer "busy".
        let freed = wait_for(Duration::from_secs(60), || {
            let a = http_get_with(&h, small, Some(READ))?;
            (!a.body.contains("busy")).then_some(a)
        });
        assert!(freed.is_some(), "the slot was never given back");
    })
    .await
    .unwrap();
    stop(mapper, session, dir).await;
}

/// Opens `/api/v1/events` on a raw connection (so the test decides when it closes): the
/// connection and the answer's status line and headers.
fn open_events(http: &str, token: Option<&str>) -> (TcpStream, String) {
    let mut s = TcpStream::connect(http).expect("connects");
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let auth = token.map_or(String::new(), |t| format!("Authorization: Bearer {t}\r\n"));
    write!(
        s,
        "GET /api/v1/events HTTP/1.1\r\nHost: {http}\r\n{auth}\r\n"
    )
    .unwrap();
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        assert_eq!(s.read(&mut byte).expect("an answer"), 1, "closed early");
        head.push(byte[0]);
    }
    (s, String::from_utf8_lossy(&head).to_lowercase())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn event_streams_over_the_cap_are_refused_and_a_closed_one_frees_its_place() {
    let dir = temp_dir("limit-streams");
    let config = MapperConfig {
        read_token: READ.into(),
        http: limits(4, 10_000, 1),
        ..MapperConfig::default()
    };
    let (mapper, session, http) = in_process_mapper_with(&dir, config).await;
    let h = http.clone();
    tokio::task::spawn_blocking(move || {
        let (_, head) = open_events(&h, None);
        assert!(head.starts_with("http/1.1 401"), "{head}");
        let (first, head) = open_events(&h, Some(READ));
        assert!(head.starts_with("http/1.1 200"), "{head}");
        let (_, head) = open_events(&h, Some(READ));
        assert!(head.starts_with("http/1.1 503"), "{head}");
        assert!(head.contains("retry-after: 1\r\n"), "{head}");
        // The client goes away: the server notices and gives the place back.
        drop(first);
        let closed = Instant::now();
        let again = wait_for(Duration::from_secs(30), || {
            let (s, head) = open_events(&h, Some(READ));
            head.starts_with("http/1.1 200").then_some(s)
        });
        assert!(again.is_some(), "a closed stream never freed its place");
        println!(
            "place given back {:.0} ms after the close",
            closed.elapsed().as_secs_f64() * 1e3
        );
        let metrics = http_get(&h, "/metrics").unwrap().1;
        assert_eq!(metric(&metrics, "levelmap_http_event_streams"), 1);
    })
    .await
    .unwrap();
    stop(mapper, session, dir).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cors_answers_the_listed_origins_only() {
    let dir = temp_dir("cors");
    let origin = "http://dashboard.example:8443";
    let config = MapperConfig {
        read_token: READ.into(),
        http: HttpConfig {
            cors_origins: vec![CorsOrigin::try_from(origin.to_owned()).unwrap()],
            ..HttpConfig::default()
        },
        ..MapperConfig::default()
    };
    let (mapper, session, addr) = in_process_mapper_with(&dir, config).await;
    let h = addr.clone();
    tokio::task::spawn_blocking(move || {
        let fleets = "/api/v1/fleets";
        // The browser's preflight (no token) before a GET with one.
        let preflight = [
            ("Origin", origin),
            ("Access-Control-Request-Method", "GET"),
            ("Access-Control-Request-Headers", "authorization"),
        ];
        let a = http_call(&h, "OPTIONS", fleets, &preflight).unwrap();
        assert_eq!(a.status, 200);
        assert_eq!(a.header("access-control-allow-origin"), Some(origin));
        let allowed = a.header("access-control-allow-headers").unwrap_or("");
        assert!(allowed.contains("authorization"), "{allowed}");
        let bearer = format!("Bearer {READ}");
        let a = http_call(
            &h,
            "GET",
            fleets,
            &[("Origin", origin), ("Authorization", &bearer)],
        );
        let a = a.unwrap();
        assert_eq!(
            (a.status, a.header("access-control-allow-origin")),
            (200, Some(origin))
        );
        let other = [
            ("Origin", "http://elsewhere.example"),
            ("Authorization", &bearer),
        ];
        let a = http_call(&h, "GET", fleets, &other).unwrap();
        assert_eq!(
            (a.status, a.header("access-control-allow-origin")),
            (200, None)
        );
    })
    .await
    .unwrap();
    stop(mapper, session, dir).await;
}
