//! The cluster's [`Blobs`]: version files in the object store `levelmap_site_versions`
//! (`sitelog::VersionFiles`), the nodes' clouds in their stream (`sitelog::Clouds`). Both
//! are opened on first use, as the servers may come up after the host.

use super::VERSION_FILES_BUCKET;
use futures_util::future::BoxFuture;
use mapper::blobs::Blobs;
use sitelog::{CloudRetention, Clouds, VersionFiles};
use tokio::sync::OnceCell;

/// The longest a cloud is waited for from the clouds' stream (a stream without a leader
/// answers only after an election).
const CLOUD_READ: std::time::Duration = std::time::Duration::from_secs(3);

/// The cluster's version files and clouds, as one host reaches them.
pub struct ClusterBlobs {
    js: sitelog::JetStream,
    /// This host's name (`[cluster] host`): its version files are filed under it.
    host: String,
    replicas: usize,
    retention: CloudRetention,
    files: OnceCell<VersionFiles>,
    clouds: OnceCell<Clouds>,
}

impl ClusterBlobs {
    /// Host `host`'s, through `js`: kept on `replicas` servers, clouds with `retention`.
    pub fn new(
        host: &str,
        js: sitelog::JetStream,
        replicas: usize,
        retention: CloudRetention,
    ) -> ClusterBlobs {
        ClusterBlobs {
            js,
            host: host.to_owned(),
            replicas,
            retention,
            files: OnceCell::new(),
            clouds: OnceCell::new(),
        }
    }

    async fn files(&self) -> Result<&VersionFiles, String> {
        self.files
            .get_or_try_init(|| VersionFiles::open(&self.js, VERSION_FILES_BUCKET, self.replicas))
            .await
            .map_err(|e| format!("the cluster's version files: {e}"))
    }
}

impl Blobs for ClusterBlobs {
    fn put_version_file<'a>(
        &'a self,
        fleet: &'a str,
        number: u64,
        file: &'a [u8],
    ) -> BoxFuture<'a, Result<String, String>> {
        Box::pin(async move {
            self.files()
                .await?
                .put(fleet, number, &self.host, file)
                .await
                .map_err(|e| format!("the version's file was not stored: {e}"))?;
            Ok(self.host.clone())
        })
    }

    fn delete_version_file<'a>(
        &'a self,
        fleet: &'a str,
        number: u64,
    ) -> BoxFuture<'a, Result<(), String>> {
        Box::pin(async move {
            self.files()
                .await?
                .delete(fleet, number)
                .await
                .map_err(|e| e.to_string())
        })
    }

    fn cloud<'a>(
        &'a self,
        fleet: &'a str,
        node: u64,
    ) -> BoxFuture<'a, Result<Option<Vec<u8>>, String>> {
        Box::pin(async move {
            let clouds = self
                .clouds
                .get_or_try_init(|| Clouds::open(self.js.clone(), self.replicas, self.retention))
                .await
                .map_err(|e| format!("the cluster's clouds: {e}"))?;
            let cloud = tokio::time::timeout(CLOUD_READ, clouds.get(fleet, node))
                .await
                .map_err(|_| "the cluster's clouds: no answer in time".to_owned())?
                .map_err(|e| format!("the cluster's clouds: {e}"))?;
            Ok(cloud.map(|c| c.to_vec()))
        })
    }
}
