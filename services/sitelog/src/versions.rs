//! The sites' map version files in a JetStream object store, one object per version
//! (`site.number`). A version's file can reach 256 MiB, over JetStream's message limit, so
//! the site's log records only that the version was added (its number and summary) and the
//! file lives here, put before that record is appended: a record never names a file that
//! was not stored. A deleted version's file is deleted after its record; a host that reads
//! the log later finds no file for it and keeps the number only.

use crate::LogError;
use crate::snapshots::{object_store, read_whole};
use async_nats::jetstream::context::Context;
use async_nats::jetstream::object_store::{DeleteErrorKind, ObjectMetadata, ObjectStore};

/// The version files bucket.
pub struct VersionFiles {
    store: ObjectStore,
}

impl VersionFiles {
    /// Opens (or creates) the object store `bucket`, kept on `replicas` servers.
    pub async fn open(
        js: &Context,
        bucket: &str,
        replicas: usize,
    ) -> Result<VersionFiles, LogError> {
        let description = "levelmap: each site's map version files";
        let store = object_store(js, bucket, description, replicas).await?;
        Ok(VersionFiles { store })
    }

    /// Stores version `number` of `site` (replacing a file put before under that number
    /// whose record was never appended).
    pub async fn put(&self, site: &str, number: u64, file: &[u8]) -> Result<(), LogError> {
        let meta = ObjectMetadata {
            name: name(site, number),
            ..Default::default()
        };
        let mut reader = file;
        self.store
            .put(meta, &mut reader)
            .await
            .map_err(LogError::jetstream)?;
        Ok(())
    }

    /// Version `number`'s file, if stored (its digest checked as it is read).
    pub async fn get(&self, site: &str, number: u64) -> Result<Option<Vec<u8>>, LogError> {
        Ok(read_whole(&self.store, &name(site, number))
            .await?
            .map(|(_, bytes)| bytes))
    }

    /// Deletes version `number`'s file; deleting one that is gone is no error.
    pub async fn delete(&self, site: &str, number: u64) -> Result<(), LogError> {
        match self.store.delete(name(site, number)).await {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == DeleteErrorKind::NotFound => Ok(()),
            Err(e) => Err(LogError::JetStream(e.to_string())),
        }
    }
}

/// The object's name: site ids are wire ids (no dot), so `site.number` is unique.
fn name(site: &str, number: u64) -> String {
    format!("{site}.{number}")
}
