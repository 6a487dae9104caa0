//! The bench's HTTP side, from outside the mapper: the event stream, timestamped on
//! receipt, and the robots' pose queries at a steady rate.

use std::collections::HashMap;
use std::io::BufRead;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// An HTTP client that hands every status back (a 404 is an answer, not an error).
pub(crate) fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build()
        .into()
}

/// Reads `/api/v1/events` and notes when each node event arrives. Blocks on the stream
/// between events; returns when the stream ends (with the mapper) or at `stop`.
pub(crate) fn follow_events(
    http: &str,
    seen: &Mutex<HashMap<(String, u64), Instant>>,
    stop: &AtomicBool,
) {
    let Ok(response) = agent()
        .get(format!("http://{http}/api/v1/events"))
        .header("Accept", "text/event-stream")
        .call()
    else {
        return;
    };
    let reader = std::io::BufReader::new(response.into_body().into_reader());
    for line in reader.lines() {
        if stop.load(Ordering::SeqCst) {
            return;
        }
        let Ok(line) = line else {
            return;
        };
        let Some(data) = line.trim_end().strip_prefix("data: ") else {
            continue;
        };
        let Ok(event) = serde_json::from_str::<serde_json::Value>(data) else {
            continue;
        };
        // A node mapped, or passed over covered ground and answered (docs/services.md,
        // "Bounded growth"): either way the robot's node is on the map now.
        if event["type"] == "node" || event["type"] == "localization" {
            let robot = event["robot"].as_str().unwrap_or_default().to_owned();
            let seq = event["node_seq"].as_u64().unwrap_or_default();
            seen.lock()
                .expect("seen")
                .entry((robot, seq))
                .or_insert_with(Instant::now);
        }
    }
}

/// GETs robot poses (`paths`, one per robot) at `rate` per second on one keep-alive
/// connection (the agent's pool of one thread's sequential requests); returns latencies (ms)
/// and errors.
pub(crate) fn query_poses(
    http: &str,
    paths: &[String],
    rate: f64,
    connection: usize,
    stop: &AtomicBool,
) -> Queried {
    let mut queried = Queried::default();
    let period = Duration::from_secs_f64(1.0 / rate.max(1.0));
    let agent = agent();
    let started = Instant::now();
    let mut k = 0u64;
    while !stop.load(Ordering::SeqCst) {
        let due = started + period * (k as u32);
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        let robot = (k as usize * 7 + connection) % paths.len();
        k += 1;
        let url = format!("http://{http}{}", paths[robot]);
        let t0 = Instant::now();
        // The body is read to the end so that the connection can be used again.
        let status = agent.get(&url).call().and_then(|mut response| {
            response.body_mut().read_to_vec()?;
            Ok(response.status().as_u16())
        });
        match status {
            Ok(200) => queried.ms.push(t0.elapsed().as_secs_f64() * 1e3),
            // 404 until the robot's first node is in: not a latency sample.
            Ok(404) => {}
            // A gateway's answer while the robot's site has no owner (cluster mode).
            Ok(503) => queried.unavailable += 1,
            _ => queried.errors += 1,
        }
    }
    queried
}

/// What one connection's pose queries got.
#[derive(Default)]
pub(crate) struct Queried {
    /// Latencies of the answered ones (ms).
    pub ms: Vec<f64>,
    /// 503s: the site had no owner then.
    pub unavailable: u64,
    /// Anything else but 200 and 404, or no answer.
    pub errors: u64,
}
