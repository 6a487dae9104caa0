//! `[source.mcap]`: a ROS 2 recording (an `.mcap` file, or a rosbag2 folder of them) played
//! through the same assembler as live topics. A reader thread walks the file and hands
//! events over a bounded channel, so a recording of any length is read at the pace the
//! service takes them (the edge's `speed` paces them; 0 is as fast as possible).

use super::ros::{RosAssembler, RosCounts, RosInputs, RosStreams};
use super::{Source, SourceEvent};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, Mutex};

/// See the module.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct McapSourceConfig {
    /// The `.mcap` file, or the rosbag2 folder (its `.mcap` files in name order).
    pub path: PathBuf,
    /// The topics and frames.
    #[serde(flatten)]
    pub streams: RosStreams,
    /// Keys no field takes: refused when the source opens (a typo must not become a
    /// default; `deny_unknown_fields` does not work beside `flatten`).
    #[serde(flatten, skip_serializing)]
    pub unknown: BTreeMap<String, toml::Value>,
}

impl Default for McapSourceConfig {
    fn default() -> Self {
        McapSourceConfig {
            path: "recording.mcap".into(),
            streams: RosStreams::default(),
            unknown: BTreeMap::new(),
        }
    }
}

/// See the module.
pub struct McapSource {
    events: Receiver<SourceEvent>,
    counts: Arc<Mutex<Option<RosCounts>>>,
}

impl McapSource {
    /// Starts reading `config.path`; an error if it has no `.mcap` file or a bad setting.
    pub fn new(config: &McapSourceConfig) -> anyhow::Result<McapSource> {
        let inputs = config.streams.inputs("[source.mcap]", &config.unknown)?;
        let files = recording_files(&config.path)?;
        let (tx, events) = sync_channel(64);
        let counts = Arc::new(Mutex::new(None));
        let done = Arc::clone(&counts);
        std::thread::Builder::new()
            .name("mcap-reader".into())
            .spawn(move || {
                let counts = read_all(&files, inputs, &tx);
                *done.lock().expect("not poisoned") = Some(counts);
            })?;
        Ok(McapSource { events, counts })
    }

    /// What the recording's samples came to, by topic, once it is read to the end.
    pub fn counts(&self) -> Option<RosCounts> {
        self.counts.lock().expect("not poisoned").clone()
    }
}

impl Source for McapSource {
    fn next_event(&mut self) -> Option<SourceEvent> {
        self.events.recv().ok()
    }
}

/// The `.mcap` file, or a folder's `.mcap` files in name order.
fn recording_files(path: &Path) -> anyhow::Result<Vec<PathBuf>> {
    if !path.is_dir() {
        anyhow::ensure!(path.exists(), "{}: no such file", path.display());
        return Ok(vec![path.to_owned()]);
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(path)
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?
        .filter_map(|e| Some(e.ok()?.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    files.sort();
    anyhow::ensure!(!files.is_empty(), "{}: no .mcap file", path.display());
    Ok(files)
}

/// Every message of `files` through the assembler, its events sent on; a file that is cut
/// short or damaged ends that file with an error naming it (what came before is used).
fn read_all(files: &[PathBuf], inputs: RosInputs, tx: &SyncSender<SourceEvent>) -> RosCounts {
    let mut assembler = RosAssembler::new(inputs);
    for file in files {
        let bytes = match std::fs::read(file) {
            Ok(b) => b,
            Err(e) => {
                tracing::error!("{}: {e}", file.display());
                continue;
            }
        };
        let stream = match mcap::MessageStream::new(&bytes) {
            Ok(s) => s,
            Err(e) => {
                tracing::error!("{}: not an MCAP file: {e}", file.display());
                continue;
            }
        };
        for message in stream {
            let message = match message {
                Ok(m) => m,
                Err(e) => {
                    tracing::error!("{}: {e}; the rest of the file is skipped", file.display());
                    break;
                }
            };
            let channel = &message.channel;
            let type_name = channel.schema.as_ref().map_or("", |s| s.name.as_str());
            if channel.message_encoding == "cdr" {
                assembler.push(&channel.topic, type_name, &message.data);
            }
            while let Some(event) = assembler.pop() {
                if tx.send(event).is_err() {
                    return assembler.counts().clone();
                }
            }
        }
    }
    let counts = assembler.counts().clone();
    tracing::info!(used = ?counts.used, refused = ?counts.refused, "recording read");
    counts
}
