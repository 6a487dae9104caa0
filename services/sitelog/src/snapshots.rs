//! The sites' map snapshots in a JetStream object store: one object per site, replaced by
//! each newer one, tagged with the log sequence it covers (every record up to it), how many
//! nodes it holds and who made it. A snapshot is derived from the log and never the record:
//! a host that takes a site over restores the map from the newest snapshot its store has
//! caught up with and replays only the log after it, rather than every node.

use crate::LogError;
use async_nats::jetstream::context::Context;
use async_nats::jetstream::object_store::{
    Config, DeleteErrorKind, GetErrorKind, InfoErrorKind, ObjectMetadata, ObjectStore,
};
use std::collections::HashMap;
use tokio::io::AsyncReadExt;

/// What a snapshot covers, as tagged on its object.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SnapshotTag {
    /// The log sequence of the last record the snapshot's map holds.
    pub log_sequence: u64,
    /// How many of the site's nodes (in log order) it holds.
    pub nodes: u64,
    /// How many of the site's solves it has applied.
    pub solves: u64,
    /// The mapping version that made it: a snapshot of another is no use to a host.
    pub mapping_version: String,
}

/// The snapshots bucket.
pub struct Snapshots {
    store: ObjectStore,
}

const LOG_SEQUENCE: &str = "log_sequence";
const NODES: &str = "nodes";
const SOLVES: &str = "solves";
const MAPPING_VERSION: &str = "mapping_version";

impl Snapshots {
    /// Opens (or creates) the object store `bucket`, kept on `replicas` servers.
    pub async fn open(js: &Context, bucket: &str, replicas: usize) -> Result<Snapshots, LogError> {
        let description = "levelmap: each site's newest map snapshot";
        let store = object_store(js, bucket, description, replicas).await?;
        Ok(Snapshots { store })
    }

    /// Replaces `site`'s snapshot with `bytes`, tagged `tag`.
    pub async fn put(&self, site: &str, tag: &SnapshotTag, bytes: &[u8]) -> Result<(), LogError> {
        let metadata = HashMap::from([
            (LOG_SEQUENCE.to_owned(), tag.log_sequence.to_string()),
            (NODES.to_owned(), tag.nodes.to_string()),
            (SOLVES.to_owned(), tag.solves.to_string()),
            (MAPPING_VERSION.to_owned(), tag.mapping_version.clone()),
        ]);
        let meta = ObjectMetadata {
            name: site.to_owned(),
            metadata,
            ..Default::default()
        };
        let mut reader = bytes;
        self.store
            .put(meta, &mut reader)
            .await
            .map_err(LogError::jetstream)?;
        Ok(())
    }

    /// The tag of `site`'s snapshot, if it has one.
    pub async fn tag(&self, site: &str) -> Result<Option<SnapshotTag>, LogError> {
        match self.store.info(site).await {
            Ok(info) if info.deleted => Ok(None),
            Ok(info) => tag_of(&info.metadata).map(Some),
            Err(e) if e.kind() == InfoErrorKind::NotFound => Ok(None),
            Err(e) => Err(LogError::JetStream(e.to_string())),
        }
    }

    /// `site`'s snapshot and its tag, if it has one. The object's digest is checked by the
    /// client as it is read.
    pub async fn get(&self, site: &str) -> Result<Option<(SnapshotTag, Vec<u8>)>, LogError> {
        match read_whole(&self.store, site).await? {
            Some((info, bytes)) => Ok(Some((tag_of(&info.metadata)?, bytes))),
            None => Ok(None),
        }
    }

    /// Deletes `site`'s snapshot; deleting what is gone is no error. A rebuilt log numbers
    /// its records anew, and a snapshot tagged with the old numbers is no use to it.
    pub async fn delete(&self, site: &str) -> Result<(), LogError> {
        match self.store.delete(site).await {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == DeleteErrorKind::NotFound => Ok(()),
            Err(e) => Err(LogError::JetStream(e.to_string())),
        }
    }
}

/// The tag kept in an object's metadata.
fn tag_of(metadata: &HashMap<String, String>) -> Result<SnapshotTag, LogError> {
    let number = |key: &str| {
        metadata
            .get(key)
            .and_then(|v| v.parse::<u64>().ok())
            .ok_or_else(|| LogError::JetStream(format!("a snapshot without a readable {key}")))
    };
    Ok(SnapshotTag {
        log_sequence: number(LOG_SEQUENCE)?,
        nodes: number(NODES)?,
        solves: number(SOLVES)?,
        mapping_version: metadata.get(MAPPING_VERSION).cloned().unwrap_or_default(),
    })
}

/// The object store `bucket`, made (on `replicas` servers) when missing.
pub(crate) async fn object_store(
    js: &Context,
    bucket: &str,
    description: &str,
    replicas: usize,
) -> Result<ObjectStore, LogError> {
    match js.get_object_store(bucket).await {
        Ok(store) => Ok(store),
        Err(_) => js
            .create_object_store(Config {
                bucket: bucket.to_owned(),
                description: Some(description.to_owned()),
                num_replicas: replicas,
                ..Default::default()
            })
            .await
            .map_err(LogError::jetstream),
    }
}

/// The whole of an object read, its digest checked by the client as it is read; `None`
/// when there is no such object.
pub(crate) async fn read_whole(
    store: &ObjectStore,
    name: &str,
) -> Result<Option<(async_nats::jetstream::object_store::ObjectInfo, Vec<u8>)>, LogError> {
    let mut object = match store.get(name).await {
        Ok(object) => object,
        Err(e) if e.kind() == GetErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(LogError::JetStream(e.to_string())),
    };
    let mut bytes = Vec::with_capacity(object.info.size);
    object
        .read_to_end(&mut bytes)
        .await
        .map_err(|e| LogError::JetStream(format!("reading {name}: {e}")))?;
    Ok(Some((object.info.clone(), bytes)))
}
