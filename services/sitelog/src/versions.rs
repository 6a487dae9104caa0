//! The sites' map version files in a JetStream object store, one object per version. A
//! version's file can reach 256 MiB, over JetStream's message limit, so the site's log
//! records only that the version was added (its number, summary and who put its file) and
//! the file lives here, put before that record is appended: a record never names a file
//! that was not stored. An object is named by site, number and the host that put it
//! (`site.number.host`): two hosts that both believed they owned the site during a takeover
//! may both put a file under one number, and only one of them appends the record; the
//! other's file never replaces the recorded one. A deleted version's files are deleted after
//! its record; a host that reads the log later finds no file for it and keeps the number
//! only.

use crate::LogError;
use crate::snapshots::{object_store, read_whole};
use async_nats::jetstream::context::Context;
use async_nats::jetstream::object_store::{DeleteErrorKind, ObjectMetadata, ObjectStore};
use futures_util::TryStreamExt;

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

    /// Stores version `number` of `site` as put by `host` (replacing a file `host` put
    /// before under that number whose record was never appended).
    pub async fn put(
        &self,
        site: &str,
        number: u64,
        host: &str,
        file: &[u8],
    ) -> Result<(), LogError> {
        let meta = ObjectMetadata {
            name: name(site, number, host),
            ..Default::default()
        };
        let mut reader = file;
        self.store
            .put(meta, &mut reader)
            .await
            .map_err(LogError::jetstream)?;
        Ok(())
    }

    /// Version `number`'s file as `host` put it, if stored (its digest checked as it is
    /// read).
    pub async fn get(
        &self,
        site: &str,
        number: u64,
        host: &str,
    ) -> Result<Option<Vec<u8>>, LogError> {
        Ok(read_whole(&self.store, &name(site, number, host))
            .await?
            .map(|(_, bytes)| bytes))
    }

    /// Deletes every file of version `number` of `site`, whoever put it; deleting what is
    /// gone is no error.
    pub async fn delete(&self, site: &str, number: u64) -> Result<(), LogError> {
        let prefix = format!("{site}.{number}.");
        let mut objects = self.store.list().await.map_err(LogError::jetstream)?;
        let mut names = Vec::new();
        while let Some(object) = objects.try_next().await.map_err(LogError::jetstream)? {
            if object.name.starts_with(&prefix) {
                names.push(object.name);
            }
        }
        for name in names {
            match self.store.delete(&name).await {
                Ok(()) => {}
                Err(e) if e.kind() == DeleteErrorKind::NotFound => {}
                Err(e) => return Err(LogError::JetStream(e.to_string())),
            }
        }
        Ok(())
    }
}

/// The object's name: site ids and host names are wire ids (no dot).
fn name(site: &str, number: u64, host: &str) -> String {
    format!("{site}.{number}.{host}")
}
