//! A recording's traffic fed to a running mapper (`levelmap mapper --from-recording`), for
//! debugging a map offline: its nodes go to the worker as [`Work::node`]s, exactly as the
//! Zenoh callback hands them over, in recorded order and as fast as the worker takes them
//! (a blocking send: a file can wait, a radio link cannot); its odometry goes through
//! [`crate::bus::odometry::on_odometry`] like live odometry, its live scans through
//! [`crate::bus::odometry::on_live_scan`]. Re-sent nodes in the recording meet
//! the worker's duplicate check as they did live. Acks are not fed.
//!
//! Where a node lands depends on the estimate when it came, so on when the network was
//! solved. The recorded mapper's `map/poses` puts say when: one after each solve, with each
//! robot's last node. The feed solves at those same points (a first pass over the file finds
//! them) and the worker's own timer is off meanwhile, so the replay rebuilds the recorded
//! map; nodes after the last recorded solve get one more at the end.

use crate::inbox::{OptimizeError, Work};
use crate::views::Shared;
use runtime::recording::RecordingReader;
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::path::Path;
use std::sync::atomic::Ordering;
use std::sync::mpsc;
use wire::{Message, Topic, v1};

/// What a recording brought.
#[derive(Clone, Debug, Default, Serialize)]
pub struct FeedReport {
    /// Messages read from the file.
    pub messages: u64,
    /// Nodes handed to the worker (re-sends included; the worker's checks decide).
    pub nodes: u64,
    /// Odometry samples taken as live odometry.
    pub odometry: u64,
    /// Live scans taken into the robots' live feeds.
    pub live_scans: u64,
    /// Acks, map poses and keys of no levelmap message: not fed.
    pub ignored: u64,
    /// Solves run where the recorded mapper solved, and after the last node.
    pub solves: u64,
    /// Each fleet fed: its last solve's report, or why it did not run.
    pub last_solve: BTreeMap<String, serde_json::Value>,
}

/// Each robot's last node_seq at a point of the recording.
type NodePoint = BTreeMap<String, u64>;

/// A recorded solve: where it was taken (empty when the recording does not say: it is
/// solved where it was applied) and where it was applied.
#[derive(Debug, Default)]
struct SolvePoint {
    taken: NodePoint,
    applied: NodePoint,
    /// Taken already by the feed.
    is_taken: bool,
}

/// Feeds every message of the recording at `path` in order, solving where the recorded
/// mapper solved and once after the last node of each fleet, and waits for each solve. A file
/// cut short or damaged is refused before anything is fed (the first pass reads it to the
/// end): an error naming it, the messages it could read and the bytes.
pub fn feed(
    path: &Path,
    work: &mpsc::SyncSender<Work>,
    shared: &Shared,
    served: &[String],
) -> anyhow::Result<FeedReport> {
    let mut points = recorded_solves(path)?;
    shared.feeding.store(true, Ordering::SeqCst);
    let fed = feed_in_order(path, work, shared, served, &mut points);
    shared.feeding.store(false, Ordering::SeqCst);
    fed
}

fn feed_in_order(
    path: &Path,
    work: &mpsc::SyncSender<Work>,
    shared: &Shared,
    served: &[String],
    points: &mut HashMap<String, VecDeque<SolvePoint>>,
) -> anyhow::Result<FeedReport> {
    let mut report = FeedReport::default();
    // Per fleet and robot, the highest node_seq fed; fleets with nodes since their last solve.
    let mut progress: HashMap<(String, String), u64> = HashMap::new();
    let mut unsolved = BTreeSet::new();
    for message in RecordingReader::open(path)? {
        let message = message?;
        report.messages += 1;
        let parsed = wire::parse_robot_key(&message.key)
            .map(|k| (k.fleet.to_owned(), k.robot.to_owned(), k.topic));
        match parsed {
            Ok((fleet, robot, Topic::Node)) => {
                // Only to know when a recorded solve is due; the worker decodes and checks.
                let node_seq = v1::Node::decode(&message.payload[..]).map(|n| n.node_seq);
                send(work, Work::node(&message.key, message.payload))?;
                report.nodes += 1;
                if !served.contains(&fleet) {
                    continue;
                }
                if let Ok(seq) = node_seq {
                    let fed = progress.entry((fleet.clone(), robot)).or_default();
                    *fed = (*fed).max(seq);
                }
                unsolved.insert(fleet.clone());
                let queue = points.entry(fleet.clone()).or_default();
                let reached = |point: &NodePoint| {
                    point.iter().all(|(robot, seq)| {
                        progress
                            .get(&(fleet.clone(), robot.clone()))
                            .is_some_and(|fed| fed >= seq)
                    })
                };
                while let Some(point) = queue.front_mut() {
                    let taking = !point.is_taken && !point.taken.is_empty();
                    if taking && reached(&point.taken) {
                        take(work, &fleet)?;
                        point.is_taken = true;
                    }
                    if (taking && !point.is_taken) || !reached(&point.applied) {
                        break;
                    }
                    let taken = point.is_taken;
                    queue.pop_front();
                    let solved = if taken {
                        apply(work, &fleet)?
                    } else {
                        solve(work, &fleet)?
                    };
                    report.last_solve.insert(fleet.clone(), solved);
                    report.solves += 1;
                    unsolved.remove(&fleet);
                }
            }
            Ok((_, _, Topic::Odom)) => {
                crate::bus::odometry::on_odometry(shared, served, &message.key, &message.payload);
                report.odometry += 1;
            }
            Ok((_, _, Topic::Scan)) => {
                crate::bus::odometry::on_live_scan(shared, served, &message.key, &message.payload);
                report.live_scans += 1;
            }
            Ok((_, _, Topic::Ack | Topic::Localization)) | Err(_) => report.ignored += 1,
        }
    }
    for fleet in unsolved {
        let solved = solve(work, &fleet)?;
        report.last_solve.insert(fleet, solved);
        report.solves += 1;
    }
    Ok(report)
}

fn send(work: &mpsc::SyncSender<Work>, job: Work) -> anyhow::Result<()> {
    work.send(job)
        .map_err(|_| anyhow::anyhow!("the mapping worker stopped"))
}

/// Asks the worker to solve `fleet` once the nodes sent before are mapped, and waits: the
/// report, or why it did not run.
fn solve(work: &mpsc::SyncSender<Work>, fleet: &str) -> anyhow::Result<serde_json::Value> {
    let (reply, answer) = tokio::sync::oneshot::channel();
    let fleet = fleet.to_owned();
    send(work, Work::Optimize { fleet, reply })?;
    report_of(answer.blocking_recv())
}

/// Asks the worker to take `fleet`'s solve once the nodes sent before are mapped, and waits.
fn take(work: &mpsc::SyncSender<Work>, fleet: &str) -> anyhow::Result<()> {
    let (reply, answer) = tokio::sync::oneshot::channel();
    let fleet = fleet.to_owned();
    send(work, Work::TakeSolve { fleet, reply })?;
    match answer.blocking_recv() {
        Ok(taken) => Ok(taken?),
        Err(_) => anyhow::bail!("the mapping worker stopped"),
    }
}

/// Asks the worker to apply the solve of `fleet` it took, and waits: the report, or why not.
fn apply(work: &mpsc::SyncSender<Work>, fleet: &str) -> anyhow::Result<serde_json::Value> {
    let (reply, answer) = tokio::sync::oneshot::channel();
    let fleet = fleet.to_owned();
    send(work, Work::ApplySolve { fleet, reply })?;
    report_of(answer.blocking_recv())
}

/// A solve request's answer: the report, or why it did not run, as JSON.
fn report_of(
    answer: Result<
        Result<serde_json::Value, OptimizeError>,
        tokio::sync::oneshot::error::RecvError,
    >,
) -> anyhow::Result<serde_json::Value> {
    let answer = answer.map_err(|_| anyhow::anyhow!("the mapping worker stopped"))?;
    Ok(answer.unwrap_or_else(|e| serde_json::Value::String(e.to_string())))
}

/// Per fleet, the solves the recorded mapper published (`levelmap/{fleet}/map/poses`), in
/// order; an undecodable one is left out.
fn recorded_solves(path: &Path) -> anyhow::Result<HashMap<String, VecDeque<SolvePoint>>> {
    let mut points: HashMap<String, VecDeque<SolvePoint>> = HashMap::new();
    for message in RecordingReader::open(path)? {
        let message = message?;
        if wire::message_name_of_key(&message.key) != Some("levelmap.v1.MapPoses") {
            continue;
        }
        let Ok(poses) = v1::MapPoses::decode(&message.payload[..]) else {
            continue;
        };
        let fleet = message.key.split('/').nth(1).unwrap_or_default().to_owned();
        let point = SolvePoint {
            taken: poses
                .solved_from
                .into_iter()
                .map(|p| (p.robot_id, p.node_seq))
                .collect(),
            applied: poses
                .poses
                .into_iter()
                .map(|p| (p.robot_id, p.node_seq))
                .collect(),
            is_taken: false,
        };
        points.entry(fleet).or_default().push_back(point);
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;
    use runtime::recording::RecordingWriter;
    use std::io::Cursor;

    #[test]
    fn a_recording_cut_mid_chunk_is_refused_naming_the_file_and_how_far_it_was_read() {
        // 500 "nodes" of 10 kB that do not compress: several chunks. The feed does not decode
        // them (the worker does), so their bytes need not be a node.
        let mut writer = RecordingWriter::new(Cursor::new(Vec::new())).unwrap();
        let mut state = 1u64;
        for i in 0..500 {
            let payload: Vec<u8> = (0..10_000)
                .map(|_| {
                    state = state.wrapping_mul(6364136223846793005).wrapping_add(1);
                    (state >> 56) as u8
                })
                .collect();
            writer
                .write("levelmap/park/robots/r1/node", &payload, i)
                .unwrap();
        }
        let bytes = writer.finish().unwrap().into_inner();
        let dir = std::env::temp_dir().join(format!("levelmap-feed-cut-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("cut.mcap");
        let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
        let chunks = &summary.chunk_indexes;
        assert!(chunks.len() >= 3, "{} chunks", chunks.len());
        let chunk = &chunks[chunks.len() / 2];
        let cut = (chunk.chunk_start_offset + chunk.chunk_length / 2) as usize;
        std::fs::write(&path, &bytes[..cut]).unwrap();

        let (work, taken) = mpsc::sync_channel(4);
        let drain = std::thread::spawn(move || taken.iter().count());
        let shared = Shared::new(String::new(), 0);
        let error = feed(&path, &work, &shared, &["park".into()]).unwrap_err();
        assert!(
            !shared.feeding.load(Ordering::SeqCst),
            "the worker's timer is back"
        );
        drop(work);
        let fed = drain.join().unwrap();

        let message = error.to_string();
        let expected = format!("{}: cut short or damaged after ", path.display());
        assert!(message.starts_with(&expected), "{message}");
        assert!(
            message.contains(&format!("({cut} bytes read)")),
            "{message}"
        );
        // The first pass (the recorded solves) reads the whole file: nothing is fed from a
        // damaged one. It read the chunks before the cut (log time i: the i-th message).
        assert_eq!(fed, 0, "nodes fed from a damaged file");
        let before = chunk.message_start_time;
        let read: u64 = message[expected.len()..]
            .split(' ')
            .next()
            .and_then(|n| n.parse().ok())
            .expect("a count");
        assert!(before > 0 && (before..500).contains(&read), "{message}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
