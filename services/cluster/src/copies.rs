//! How many copies of each owned site's log are current, read every [`EVERY`] into
//! `/metrics` (`levelmap_site_log_copies_current{site}`): a NATS server down, behind or with
//! its JetStream disabled (a full disk) shows there while the log still goes on, before one
//! more loss stops it.

use super::Host;
use std::collections::HashSet;
use std::sync::Arc;
use std::time::Duration;

/// How often the copies are read: one stream-info request per owned site.
const EVERY: Duration = Duration::from_secs(10);

/// A read that takes longer is skipped (a stream electing its leader answers late).
const BOUND: Duration = Duration::from_secs(2);

/// Reads the copies of every site this host holds, until the mapper stops; a site no longer
/// held leaves the metric.
pub(super) async fn watch(host: Arc<Host>) {
    let copies = &host.shared.instruments.log_copies_current;
    let label = |site: &str| vec![("site".to_owned(), site.to_owned())];
    let mut stopping = host.shared.stopping.subscribe();
    let mut shown = HashSet::new();
    loop {
        let held: HashSet<String> = host
            .held
            .lock()
            .expect("leases lock")
            .keys()
            .filter(|key| !super::presence::is_presence_key(key))
            .cloned()
            .collect();
        for site in &held {
            match sitelog::within(BOUND, sitelog::log_copies(&host.js, site)).await {
                Ok((current, _)) => {
                    copies.get_or_create(&label(site)).set(current as i64);
                    shown.insert(site.clone());
                }
                Err(e) => tracing::debug!(site, "cluster: the log's copies not read: {e}"),
            }
        }
        shown.retain(|site: &String| {
            let keep = held.contains(site);
            if !keep {
                copies.remove(&label(site));
            }
            keep
        });
        tokio::select! {
            _ = tokio::time::sleep(EVERY) => {}
            _ = stopping.changed() => return,
        }
    }
}
