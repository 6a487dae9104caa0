//! Changes of a site's record that an operator asks for (versions added or deleted, robots'
//! modes set): checked here, then handed to the worker, which journals them as it journals
//! nodes ([`crate::journal`]). The API never writes the store.

use super::{Api, ApiError, Reply};
use crate::inbox::Work;
use crate::journal::ChangeError;
use crate::store::SiteChange;
use runtime::session::now_ns;

impl Api {
    /// Journals `change` of `fleet` (`file`: an added version's file) through the worker.
    /// 503 when the worker stops, or in cluster mode when this host does not hold the site
    /// or its log does not take the change.
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
        // Not the owner, the log not reached, or the store failed: each is answered by
        // asking again (a gateway finds the owner).
        done.await
            .map_err(|_| stopped())?
            .map_err(|e: ChangeError| ApiError::Unavailable(e.to_string()))
    }
}
