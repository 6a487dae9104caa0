//! Cluster mode: what the API reaches beyond this host. A change of a site's versions or
//! modes goes through the site's log, so it moves with the site: the API checks it here on
//! the owner, puts an added version's file in the cluster's version files, and hands the
//! change to the worker, which appends it to the log (fenced like a batch) and then stores
//! it. A node's cloud that this host's store lacks (the node came before a takeover) is read
//! from the clouds' stream.

use super::{Api, ApiError, Reply};
use crate::cluster::VERSION_FILES_BUCKET;
use crate::store::SiteChange;
use crate::worker::{ChangeError, Work};
use runtime::session::now_ns;
use sitelog::{CloudRetention, Clouds, VersionFiles};
use tokio::sync::OnceCell;

/// The longest a cloud is waited for from the clouds' stream (a stream without a leader
/// answers only after an election).
const CLOUD_READ: std::time::Duration = std::time::Duration::from_secs(3);

/// The cluster's stores the API reads and writes: opened on first use, as the servers may
/// come up after the host.
pub struct ClusterStores {
    js: sitelog::JetStream,
    /// This host's name (`[cluster] host`).
    pub(super) host: String,
    replicas: usize,
    retention: CloudRetention,
    files: OnceCell<VersionFiles>,
    clouds: OnceCell<Clouds>,
}

impl ClusterStores {
    /// Host `host`'s, through `js`: kept on `replicas` servers, clouds with `retention`.
    pub fn new(
        host: &str,
        js: sitelog::JetStream,
        replicas: usize,
        retention: CloudRetention,
    ) -> ClusterStores {
        ClusterStores {
            js,
            host: host.to_owned(),
            replicas,
            retention,
            files: OnceCell::new(),
            clouds: OnceCell::new(),
        }
    }

    /// The version files.
    pub(super) async fn files(&self) -> Reply<&VersionFiles> {
        self.files
            .get_or_try_init(|| VersionFiles::open(&self.js, VERSION_FILES_BUCKET, self.replicas))
            .await
            .map_err(|e| ApiError::Unavailable(format!("the cluster's version files: {e}")))
    }

    /// Node `node`'s cloud of `fleet` from the clouds' stream, if it is kept there.
    pub(super) async fn cloud(&self, fleet: &str, node: u64) -> Reply<Option<Vec<u8>>> {
        let clouds = self
            .clouds
            .get_or_try_init(|| Clouds::open(self.js.clone(), self.replicas, self.retention))
            .await
            .map_err(|e| ApiError::Unavailable(format!("the cluster's clouds: {e}")))?;
        let cloud = tokio::time::timeout(CLOUD_READ, clouds.get(fleet, node))
            .await
            .map_err(|_| ApiError::Unavailable("the cluster's clouds: no answer in time".into()))?
            .map_err(|e| ApiError::Unavailable(format!("the cluster's clouds: {e}")))?;
        Ok(cloud.map(|c| c.to_vec()))
    }
}

impl Api {
    /// Appends `change` to `fleet`'s log and stores it (`file`: an added version's file, in
    /// the version files already). 503 when this host does not hold the site.
    pub(super) async fn change_site(
        &self,
        fleet: &str,
        change: SiteChange,
        file: Option<Vec<u8>>,
    ) -> Reply<()> {
        let (reply, done) = tokio::sync::oneshot::channel();
        let work = Work::Change {
            site: fleet.to_owned(),
            change: Box::new(change),
            file,
            asked_ns: now_ns(),
            reply,
        };
        let stopped = || ApiError::Unavailable("the mapping worker stopped".into());
        let queue = self.work.clone();
        tokio::task::spawn_blocking(move || queue.send(work))
            .await
            .map_err(ApiError::internal)?
            .map_err(|_| stopped())?;
        // Not the owner, the log not reached, or the store failed after the log took it:
        // each is answered by asking again (a gateway finds the owner).
        done.await
            .map_err(|_| stopped())?
            .map_err(|e: ChangeError| ApiError::Unavailable(e.to_string()))
    }

    /// [`Api::change_site`] from a blocking thread (a heavy request's work).
    pub(super) fn change_site_blocking(
        &self,
        fleet: &str,
        change: SiteChange,
        file: Option<Vec<u8>>,
    ) -> Reply<()> {
        tokio::runtime::Handle::current().block_on(self.change_site(fleet, change, file))
    }
}
