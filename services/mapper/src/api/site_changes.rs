//! Cluster mode: a change of a site's versions or modes goes through the site's log, so it
//! moves with the site. The API checks it here on the owner, puts an added version's file in
//! the cluster's version files, and hands the change to the worker, which appends it to the
//! log (fenced like a batch) and then stores it.

use super::{Api, ApiError, Reply};
use crate::cluster::VERSION_FILES_BUCKET;
use crate::store::SiteChange;
use crate::worker::{ChangeError, Work};
use runtime::session::now_ns;
use sitelog::VersionFiles;
use tokio::sync::OnceCell;

/// What a cluster host's API needs to change a site's versions and modes.
pub struct SiteChanges {
    js: sitelog::JetStream,
    replicas: usize,
    /// Opened on first use: the servers may come up after the host.
    files: OnceCell<VersionFiles>,
}

impl SiteChanges {
    /// Through `js`, its buckets kept on `replicas` servers.
    pub fn new(js: sitelog::JetStream, replicas: usize) -> SiteChanges {
        SiteChanges {
            js,
            replicas,
            files: OnceCell::new(),
        }
    }

    /// The version files.
    pub(super) async fn files(&self) -> Reply<&VersionFiles> {
        self.files
            .get_or_try_init(|| VersionFiles::open(&self.js, VERSION_FILES_BUCKET, self.replicas))
            .await
            .map_err(|e| ApiError::Unavailable(format!("the cluster's version files: {e}")))
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
            change,
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
