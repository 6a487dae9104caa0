//! The teleoperation side of the bench: clients of robots' live feeds (`…/robots/{robot}/live`,
//! server-sent events), and the map windows around robots (`…/robots/{robot}/map.png`).

use super::{FLEET, Percentiles, agent};
use serde::Serialize;
use std::io::BufRead;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// What one live client saw.
pub(super) struct LiveClient {
    /// Odometry stamp → receipt (ms), the same clock (the bench stamps odometry with it).
    delays_ms: Vec<f64>,
    /// Samples received between `from` and the stop.
    samples: usize,
    /// When its first sample came.
    first: Option<Instant>,
}

/// The live clients' figures.
#[derive(Serialize, Default)]
pub(super) struct LiveReport {
    clients: usize,
    /// Odometry stamp → client receipt, every sample of every client.
    odometry_to_client: Percentiles,
    /// Samples per second of the slowest client and the median one, from its first sample on.
    samples_per_s_min: f64,
    samples_per_s_median: f64,
}

/// Follows robot `robot`'s live feed until `stop`; asks again while the feed is not there
/// yet (404 before the robot's first odometry).
pub(super) fn follow_live(http: &str, robot: usize, stop: &AtomicBool) -> LiveClient {
    let mut client = LiveClient {
        delays_ms: Vec::new(),
        samples: 0,
        first: None,
    };
    let url = format!("http://{http}/api/v1/fleets/{FLEET}/robots/robot{robot}/live");
    while !stop.load(Ordering::SeqCst) {
        let response = match agent().get(&url).call() {
            Ok(r) if r.status() == 200 => r,
            _ => {
                std::thread::sleep(Duration::from_millis(100));
                continue;
            }
        };
        let reader = std::io::BufReader::new(response.into_body().into_reader());
        for line in reader.lines() {
            let Ok(line) = line else { break };
            if stop.load(Ordering::SeqCst) {
                return client;
            }
            let Some(data) = line.trim_end().strip_prefix("data: ") else {
                continue;
            };
            let now_ns = runtime::session::now_ns();
            let Ok(sample) = serde_json::from_str::<serde_json::Value>(data) else {
                continue;
            };
            let stamp = sample["stamp_ns"].as_u64().unwrap_or(now_ns);
            client.first.get_or_insert_with(Instant::now);
            client.samples += 1;
            client
                .delays_ms
                .push(now_ns.saturating_sub(stamp) as f64 * 1e-6);
        }
    }
    client
}

impl LiveReport {
    /// The figures of `clients`, stopped at `stopped`.
    pub(super) fn of(clients: Vec<LiveClient>, stopped: Instant) -> LiveReport {
        let mut rates: Vec<f64> = clients
            .iter()
            .map(|c| {
                c.first.map_or(0.0, |t| {
                    let s = stopped.saturating_duration_since(t).as_secs_f64();
                    if s > 0.0 { c.samples as f64 / s } else { 0.0 }
                })
            })
            .collect();
        rates.sort_by(f64::total_cmp);
        LiveReport {
            clients: clients.len(),
            samples_per_s_min: rates.first().copied().unwrap_or(0.0),
            samples_per_s_median: rates.get(rates.len() / 2).copied().unwrap_or(0.0),
            odometry_to_client: Percentiles::of(
                clients.into_iter().flat_map(|c| c.delays_ms).collect(),
            ),
        }
    }
}

/// The map windows' figures: the first window around each robot (tiles made), then the same
/// windows again (from the tiles).
#[derive(Serialize, Default)]
pub(super) struct WindowReport {
    radius_m: f64,
    resolution_m: f64,
    first: Percentiles,
    again: Percentiles,
}

/// GETs a 40 m window at 0.1 m around `robots` robots, twice each.
pub(super) fn query_windows(http: &str, robots: usize) -> WindowReport {
    let agent = agent();
    let mut rounds = [Vec::new(), Vec::new()];
    for round in &mut rounds {
        for robot in 0..robots {
            let url = format!(
                "http://{http}/api/v1/fleets/{FLEET}/robots/robot{robot}/map.png?radius_m=20&resolution_m=0.1"
            );
            let t0 = Instant::now();
            let ok = agent
                .get(&url)
                .call()
                .is_ok_and(|mut r| r.status() == 200 && r.body_mut().read_to_vec().is_ok());
            if ok {
                round.push(t0.elapsed().as_secs_f64() * 1e3);
            }
        }
    }
    let [first, again] = rounds;
    WindowReport {
        radius_m: 20.0,
        resolution_m: 0.1,
        first: Percentiles::of(first),
        again: Percentiles::of(again),
    }
}
