//! The nodes' 3D clouds in cluster mode, apart from the sites' logs: a cloud is not the
//! record (a map is made and restored without it), so it is put after its node is acked and
//! kept with a retention of its own. One stream for every site (`LEVELMAP_CLOUDS`), one
//! subject per node (`levelmap.cloud.{site}.{node}`, its last message kept), its age and
//! bytes bounded by the stream; a host reads a node's cloud by its subject, whichever host
//! put it.

use crate::LogError;
use async_nats::jetstream::context::Context;
use async_nats::jetstream::message::PublishMessage;
use async_nats::jetstream::stream::{
    Config, DiscardPolicy, LastRawMessageErrorKind, StorageType, Stream,
};
use bytes::Bytes;
use std::time::Duration;

/// The clouds' stream.
pub const CLOUDS_STREAM: &str = "LEVELMAP_CLOUDS";

/// How long and how much the clouds' stream keeps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CloudRetention {
    /// Clouds older than this are dropped; `None`: however old.
    pub max_age: Option<Duration>,
    /// The oldest clouds are dropped beyond this many bytes (every site's together);
    /// `None`: no bound.
    pub max_bytes: Option<u64>,
}

/// The clouds' stream, to put and read clouds.
pub struct Clouds {
    js: Context,
    stream: Stream,
}

impl Clouds {
    /// Opens the clouds' stream, made (on `replicas` servers, with `retention`) if missing.
    pub async fn open(
        js: Context,
        replicas: usize,
        retention: CloudRetention,
    ) -> Result<Clouds, LogError> {
        let mut config = Config {
            name: CLOUDS_STREAM.to_owned(),
            subjects: vec!["levelmap.cloud.>".to_owned()],
            storage: StorageType::File,
            num_replicas: replicas,
            max_messages_per_subject: 1,
            discard: DiscardPolicy::Old,
            duplicate_window: Duration::from_secs(120),
            ..Default::default()
        };
        if let Some(age) = retention.max_age {
            config.max_age = age;
        }
        if let Some(bytes) = retention.max_bytes {
            config.max_bytes = i64::try_from(bytes).unwrap_or(i64::MAX);
        }
        let reserved = config.max_bytes;
        let stream = js.get_or_create_stream(config).await.map_err(|e| {
            let refused = e.to_string();
            if !refused.contains("insufficient storage") {
                return LogError::jetstream(refused);
            }
            LogError::JetStream(format!(
                "{refused}: the clouds' stream reserves {reserved} bytes on each of {replicas} \
                 servers, more than their JetStream file storage has free; raise each \
                 server's `jetstream {{ max_file_store }}` (its default follows the disk's \
                 free space), or lower the hosts' `[clouds] max_bytes`"
            ))
        })?;
        Ok(Clouds { js, stream })
    }

    /// Puts node `node`'s cloud of `site`; done once JetStream acked it. Put twice, it is
    /// stored once.
    pub async fn put(&self, site: &str, node: u64, cloud: Bytes) -> Result<(), LogError> {
        let publish = PublishMessage::build()
            .payload(cloud)
            .message_id(format!("{site}/{node}"));
        self.js
            .send_publish(subject(site, node), publish)
            .await
            .map_err(LogError::jetstream)?
            .await
            .map_err(LogError::jetstream)?;
        Ok(())
    }

    /// Node `node`'s cloud of `site`, if one was put and is still kept.
    pub async fn get(&self, site: &str, node: u64) -> Result<Option<Bytes>, LogError> {
        match self
            .stream
            .get_last_raw_message_by_subject(&subject(site, node))
            .await
        {
            Ok(message) => Ok(Some(message.payload)),
            Err(e) if e.kind() == LastRawMessageErrorKind::NoMessageFound => Ok(None),
            Err(e) => Err(LogError::JetStream(e.to_string())),
        }
    }
}

/// Node `node`'s subject (site ids have no dot).
fn subject(site: &str, node: u64) -> String {
    format!("levelmap.cloud.{site}.{node}")
}
