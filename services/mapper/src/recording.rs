//! A recording's traffic fed to a running mapper (`levelmap mapper --from-recording`), for
//! debugging a map offline: its nodes go to the worker as [`Work::node`]s, exactly as the
//! Zenoh callback hands them over, in recorded order and as fast as the worker takes them
//! (a blocking send: a file can wait, a radio link cannot); its odometry goes through
//! [`crate::odometry::on_odometry`] like live odometry. Acks and map poses are the mapper's
//! own output: they are read and counted, never fed. Re-sent nodes in the recording meet the
//! worker's duplicate check as they did live.

use crate::state::Shared;
use crate::worker::{OptimizeReply, Work};
use serde::Serialize;
use std::collections::BTreeSet;
use std::path::Path;
use std::sync::mpsc;
use wire::Topic;
use wire::recording::RecordingReader;

/// What a recording brought.
#[derive(Clone, Debug, Default, Serialize)]
pub struct FeedReport {
    /// Messages read from the file.
    pub messages: u64,
    /// Nodes handed to the worker (re-sends included; the worker's checks decide).
    pub nodes: u64,
    /// Odometry samples taken as live odometry.
    pub odometry: u64,
    /// Acks, map poses and keys of no levelmap message: not fed.
    pub ignored: u64,
    /// The fleets whose nodes were fed, each solved once after its last node.
    pub fleets: Vec<String>,
}

/// Feeds every message of the recording at `path` in order, then asks the worker for one
/// solve per fleet fed (queued behind the nodes: it comes after the last of them). Returns
/// the report and the solves' replies. A file cut short or damaged is an error naming it,
/// the messages read and the bytes; what came before it was fed.
pub fn feed(
    path: &Path,
    work: &mpsc::SyncSender<Work>,
    shared: &Shared,
    served: &[String],
) -> anyhow::Result<(FeedReport, Vec<OptimizeAnswer>)> {
    let stopped = || anyhow::anyhow!("the mapping worker stopped");
    let mut report = FeedReport::default();
    let mut fleets = BTreeSet::new();
    for message in RecordingReader::open(path)? {
        let message = message?;
        report.messages += 1;
        match wire::parse_robot_key(&message.key).map(|k| (k.fleet.to_owned(), k.topic)) {
            Ok((fleet, Topic::Node)) => {
                fleets.insert(fleet);
                work.send(Work::node(&message.key, message.payload))
                    .map_err(|_| stopped())?;
                report.nodes += 1;
            }
            Ok((_, Topic::Odom)) => {
                crate::odometry::on_odometry(shared, served, &message.key, &message.payload);
                report.odometry += 1;
            }
            Ok((_, Topic::Ack)) | Err(_) => report.ignored += 1,
        }
    }
    fleets.retain(|f| served.contains(f));
    let mut answers = Vec::new();
    for fleet in &fleets {
        let (reply, answer): (OptimizeReply, _) = tokio::sync::oneshot::channel();
        let fleet = fleet.clone();
        work.send(Work::Optimize { fleet, reply })
            .map_err(|_| stopped())?;
        answers.push(answer);
    }
    report.fleets = fleets.into_iter().collect();
    Ok((report, answers))
}

/// The worker's answer to one of the final solves.
pub type OptimizeAnswer =
    tokio::sync::oneshot::Receiver<Result<serde_json::Value, crate::worker::OptimizeError>>;

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;
    use wire::recording::RecordingWriter;

    #[test]
    fn a_recording_cut_mid_chunk_fails_naming_the_file_and_how_far_it_was_read() {
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
        drop(work);
        let fed = drain.join().unwrap();

        let message = error.to_string();
        let expected = format!("{}: cut short or damaged after ", path.display());
        assert!(message.starts_with(&expected), "{message}");
        assert!(
            message.contains(&format!("({cut} bytes read)")),
            "{message}"
        );
        // The messages of the chunks before the cut were fed (log time i: the i-th message).
        let before = chunk.message_start_time as usize;
        assert!(
            before > 0 && (before..500).contains(&fed),
            "{fed} of {before} fed"
        );
        assert!(
            message.contains(&format!("after {fed} messages")),
            "{message}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
