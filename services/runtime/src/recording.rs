//! MCAP recordings of levelmap traffic (`levelmap record`, `levelmap mapper --from-recording`):
//! one channel per Zenoh key (the topic is the key), each message as it was on the bus,
//! protobuf-encoded, with [`wire::DESCRIPTOR_SET`] as the schema data of every channel's
//! message type (Foxglove's convention for protobuf in MCAP). No I/O of its own beyond the
//! writer or file it is given, and no clock: the caller stamps each message.

use anyhow::{Context, anyhow};
use mcap::records::{MessageHeader, Record};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use prost::Message;
use std::collections::{BTreeMap, HashMap};
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};
use wire::{DESCRIPTOR_SET, message_name_of_key, v1};

/// Writes levelmap messages into an MCAP, its summary and chunk indexes on [`Self::finish`].
pub struct RecordingWriter<W: Write + Seek> {
    writer: mcap::Writer<W>,
    schemas: HashMap<String, u16>,
    channels: HashMap<String, u16>,
    sequence: u32,
}

impl<W: Write + Seek> RecordingWriter<W> {
    /// An empty recording over `out` (zstd chunks, the writer's defaults).
    pub fn new(out: W) -> anyhow::Result<Self> {
        let writer = mcap::WriteOptions::new()
            .library(concat!("levelmap/", env!("CARGO_PKG_VERSION")))
            .create(out)?;
        Ok(RecordingWriter {
            writer,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            sequence: 0,
        })
    }

    /// Writes one message received on `key` at `log_time_ns` (ns since the Unix epoch); its
    /// publish time is its header's stamp when it has one. `Ok(false)`: not a levelmap key,
    /// nothing written.
    pub fn write(&mut self, key: &str, payload: &[u8], log_time_ns: u64) -> anyhow::Result<bool> {
        let Some(name) = message_name_of_key(key) else {
            return Ok(false);
        };
        let channel_id = match self.channels.get(key) {
            Some(&id) => id,
            None => self.add_channel(key, name)?,
        };
        self.sequence = self.sequence.wrapping_add(1);
        let header = MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: log_time_ns,
            publish_time: header_stamp_ns(name, payload).unwrap_or(log_time_ns),
        };
        self.writer.write_to_known_channel(&header, payload)?;
        Ok(true)
    }

    fn add_channel(&mut self, key: &str, name: &str) -> anyhow::Result<u16> {
        self.channel(
            key,
            &SchemaOf {
                name,
                encoding: "protobuf",
                data: DESCRIPTOR_SET,
            },
        )
    }

    /// The channel of `topic`, added with `schema` the first time.
    fn channel(&mut self, topic: &str, schema: &SchemaOf<'_>) -> anyhow::Result<u16> {
        if let Some(&id) = self.channels.get(topic) {
            return Ok(id);
        }
        let schema_id = match self.schemas.get(schema.name) {
            Some(&id) => id,
            None => {
                let id = self
                    .writer
                    .add_schema(schema.name, schema.encoding, schema.data)?;
                self.schemas.insert(schema.name.to_owned(), id);
                id
            }
        };
        let id = self
            .writer
            .add_channel(schema_id, topic, "protobuf", &BTreeMap::new())?;
        self.channels.insert(topic.to_owned(), id);
        Ok(id)
    }

    /// Writes one protobuf message of another schema (Foxglove's, `levelmap record
    /// --foxglove`) on `topic`, measured at `publish_time_ns` (0: `log_time_ns`).
    pub fn write_other(
        &mut self,
        topic: &str,
        schema: &SchemaOf<'_>,
        payload: &[u8],
        log_time_ns: u64,
        publish_time_ns: u64,
    ) -> anyhow::Result<()> {
        let channel_id = self.channel(topic, schema)?;
        self.sequence = self.sequence.wrapping_add(1);
        let header = MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: log_time_ns,
            publish_time: if publish_time_ns == 0 {
                log_time_ns
            } else {
                publish_time_ns
            },
        };
        self.writer.write_to_known_channel(&header, payload)?;
        Ok(())
    }

    /// Ends the recording: the last chunk, the summary (schemas, channels, statistics, chunk
    /// indexes) and the footer.
    pub fn finish(mut self) -> anyhow::Result<W> {
        self.writer.finish()?;
        Ok(self.writer.into_inner())
    }
}

/// A channel's schema: its name, encoding and data.
pub struct SchemaOf<'a> {
    /// Its name (`foxglove.LaserScan`).
    pub name: &'a str,
    /// Its encoding (`protobuf`: the data is a `FileDescriptorSet`).
    pub encoding: &'a str,
    /// The schema itself.
    pub data: &'a [u8],
}

/// The leading `Header` (field 1) of the messages that have one.
#[derive(Clone, PartialEq, prost::Message)]
struct HeaderOnly {
    #[prost(message, optional, tag = "1")]
    header: Option<v1::Header>,
}

/// The measurement time a message's header carries (Node, Odometry, Ack, LiveScan); `None`
/// without one.
fn header_stamp_ns(name: &str, payload: &[u8]) -> Option<u64> {
    if !matches!(
        name,
        "levelmap.v1.Node" | "levelmap.v1.Odometry" | "levelmap.v1.Ack" | "levelmap.v1.LiveScan"
    ) {
        return None;
    }
    let stamp = HeaderOnly::decode(payload).ok()?.header?.stamp_ns;
    (stamp > 0).then_some(stamp)
}

/// The largest record a reader takes (a chunk holds at most the writer's chunk size plus one
/// message, and a message at most [`wire::MAX_NODE_BYTES`]): a damaged length field is an
/// error, not an allocation of gigabytes.
pub const MAX_RECORD_BYTES: usize = 4 * wire::MAX_NODE_BYTES;

/// One message of a recording.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RecordedMessage {
    /// The Zenoh key it came on (the channel's topic).
    pub key: String,
    /// When the recorder received it (ns since the Unix epoch).
    pub log_time_ns: u64,
    /// Its bytes, as they were on the bus.
    pub payload: Vec<u8>,
}

/// The messages of a recording file in the order they were written, read as a stream (a
/// chunk at a time, whatever the file's size). A file cut short or damaged yields one error
/// naming the file, the messages read before it and how far into the file it was; nothing
/// after it.
pub struct RecordingReader<R: Read = std::fs::File> {
    source: R,
    path: PathBuf,
    reader: LinearReader,
    topics: HashMap<u16, String>,
    bytes_read: u64,
    messages: u64,
    failed: bool,
}

impl RecordingReader {
    /// Opens `path`.
    pub fn open(path: &Path) -> anyhow::Result<RecordingReader> {
        let file = std::fs::File::open(path)
            .with_context(|| format!("{}: cannot open", path.display()))?;
        Ok(RecordingReader::new(file, path))
    }
}

impl<R: Read> RecordingReader<R> {
    /// Reads `source`; `path` names it in errors.
    pub fn new(source: R, path: &Path) -> RecordingReader<R> {
        RecordingReader {
            source,
            path: path.to_owned(),
            reader: LinearReader::new_with_options(
                LinearReaderOptions::default().with_record_length_limit(MAX_RECORD_BYTES),
            ),
            topics: HashMap::new(),
            bytes_read: 0,
            messages: 0,
            failed: false,
        }
    }

    /// Messages read so far.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    fn error(&mut self, what: impl std::fmt::Display) -> anyhow::Error {
        self.failed = true;
        anyhow!(
            "{}: cut short or damaged after {} messages ({} bytes read): {what}",
            self.path.display(),
            self.messages,
            self.bytes_read
        )
    }

    /// The next message, `None` at the end of the file.
    fn next_message(&mut self) -> Option<anyhow::Result<RecordedMessage>> {
        loop {
            let event = match self.reader.next_event()? {
                Ok(event) => event,
                Err(e) => return Some(Err(self.error(e))),
            };
            let (opcode, data) = match event {
                LinearReadEvent::ReadRequest(wanted) => {
                    let buffer = self.reader.insert(wanted);
                    match self.source.read(buffer) {
                        Ok(read) => {
                            self.reader.notify_read(read);
                            self.bytes_read += read as u64;
                        }
                        Err(e) => return Some(Err(self.error(e))),
                    }
                    continue;
                }
                LinearReadEvent::Record { data, opcode } => (opcode, data),
            };
            match mcap::parse_record(opcode, data) {
                Ok(Record::Channel(channel)) => {
                    self.topics.insert(channel.id, channel.topic);
                }
                Ok(Record::Message { header, data }) => {
                    let payload = data.into_owned();
                    let Some(key) = self.topics.get(&header.channel_id).cloned() else {
                        let why = format!("a message on unknown channel {}", header.channel_id);
                        return Some(Err(self.error(why)));
                    };
                    self.messages += 1;
                    return Some(Ok(RecordedMessage {
                        key,
                        log_time_ns: header.log_time,
                        payload,
                    }));
                }
                Ok(_) => {}
                Err(e) => return Some(Err(self.error(e))),
            }
        }
    }
}

impl<R: Read> Iterator for RecordingReader<R> {
    type Item = anyhow::Result<RecordedMessage>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        self.next_message()
    }
}

#[cfg(test)]
mod tests;
