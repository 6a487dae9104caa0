//! Stopping: SIGTERM (what `systemctl stop` sends) stops the mapper gracefully, with an event
//! stream open; and `levelmap demo` exits after its summary while a dashboard holds an event
//! stream (it used to wait for that stream forever).

mod common;

use common::*;
use std::io::BufRead;
use std::process::{Child, ExitStatus};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Follows `/api/v1/events` on a thread; the receiver gets `()` when the stream ends.
fn open_event_stream(http: &str) -> mpsc::Receiver<()> {
    let (ended, rx) = mpsc::channel();
    let url = format!("http://{http}/api/v1/events");
    let (opened_tx, opened) = mpsc::channel();
    std::thread::spawn(move || {
        // No timeout: the stream is meant to stay open until the server ends it.
        let agent: ureq::Agent = ureq::Agent::config_builder().build().into();
        let response = agent.get(&url).call().expect("the event stream opens");
        let _ = opened_tx.send(());
        let reader = std::io::BufReader::new(response.into_body().into_reader());
        for line in reader.lines() {
            if line.is_err() {
                break;
            }
        }
        let _ = ended.send(());
    });
    opened
        .recv_timeout(Duration::from_secs(10))
        .expect("the event stream answered");
    rx
}

/// The child's exit within `timeout`; kills it and fails the test otherwise.
fn exits_within(child: &mut Child, timeout: Duration, what: &str) -> ExitStatus {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(status) = child.try_wait().expect("try_wait") {
            return status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{what} did not exit within {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn sigterm_stops_the_mapper_gracefully_with_an_event_stream_open() {
    let dir = temp_dir("sigterm");
    let mut mapper = MapperProcess::start(&dir);
    let stream = open_event_stream(&mapper.http);
    sigterm(mapper.child());
    let status = exits_within(mapper.child(), Duration::from_secs(20), "levelmap mapper");
    // Killed by the signal, the status would have no code; a graceful stop exits 0.
    assert_eq!(status.code(), Some(0), "{status}");
    stream
        .recv_timeout(Duration::from_secs(5))
        .expect("the event stream ended with the mapper");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_demo_exits_after_its_summary_with_a_dashboard_open() {
    let dir = temp_dir("demo-exit");
    let http = format!("127.0.0.1:{}", free_port());
    let zenoh = format!("tcp/127.0.0.1:{}", free_port());
    // 16 s of park at 2x: long enough to open a stream while the robots drive.
    let mut demo = levelmap()
        .args(["demo", "--duration", "16", "--speed", "2", "--json"])
        .args(["--http", &http, "--zenoh", &zenoh, "--dir"])
        .arg(dir.join("demo"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .map(KillOnDrop::from)
        .expect("levelmap demo starts");
    let up = wait_for(Duration::from_secs(30), || http_get(&http, "/healthz"));
    assert!(up.is_some(), "the demo's mapper did not answer");
    let stream = open_event_stream(&http);
    let status = exits_within(&mut demo, Duration::from_secs(120), "levelmap demo");
    assert!(status.success(), "{status}");
    let mut out = String::new();
    std::io::Read::read_to_string(demo.stdout.as_mut().expect("stdout"), &mut out).unwrap();
    let report: serde_json::Value = serde_json::from_str(&out).expect("the demo's JSON report");
    assert!(report["nodes"].as_u64().unwrap() > 0, "{report}");
    stream
        .recv_timeout(Duration::from_secs(5))
        .expect("the event stream ended with the demo");
    std::fs::remove_dir_all(&dir).ok();
}
