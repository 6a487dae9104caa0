//! Which mapper hosts are alive, as the leases bucket says: each host holds a lease of its
//! own, `host.<name>`, while it runs (renewed as the sites' are, released on a graceful
//! stop). Keys with a dot are no fleet id, so they never meet a site's. The sites' orders
//! are taken over the live hosts: the first live host in a site's order claims it at once
//! and the next one stands by; and a holder hands a site back to a live host before it in
//! the order once that host has been seen alive for `hand_back_after_ms`, so that a host
//! started (or back after a fault) gets its own sites and only those.
//!
//! The bucket is the source of truth for ownership already; taking liveness from it too
//! means a host that cannot reach NATS is not counted alive, whatever else it reaches. What
//! Zenoh adds (the `tokens` module): a host whose liveliness token was seen to go is not kept alive
//! through a bucket's election on what was known before.

use super::Host;
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The lease key of a host's presence.
pub(super) fn presence_key(host: &str) -> String {
    format!("host.{host}")
}

/// Whether a lease key is a host's presence rather than a site's.
pub(super) fn is_presence_key(key: &str) -> bool {
    key.starts_with("host.")
}

/// The live hosts as this host last read them, with when it first saw each alive.
#[derive(Default)]
pub(super) struct Presence {
    /// `None` until the first reading.
    live: Mutex<Option<BTreeMap<String, Instant>>>,
}

impl Presence {
    /// `order` without the hosts not alive (this host always is); `None` before the first
    /// reading.
    pub fn live_order<'h>(&self, order: &[&'h str], this: &str) -> Option<Vec<&'h str>> {
        let live = self.live.lock().expect("presence lock");
        let live = live.as_ref()?;
        Some(
            order
                .iter()
                .copied()
                .filter(|h| *h == this || live.contains_key(*h))
                .collect(),
        )
    }

    /// The first host of `order` before `this` seen alive for at least `settled`: where
    /// the site belongs, if not here.
    pub fn home_before<'h>(
        &self,
        order: &[&'h str],
        this: &str,
        settled: Duration,
    ) -> Option<&'h str> {
        let live = self.live.lock().expect("presence lock");
        let live = live.as_ref()?;
        order
            .iter()
            .take_while(|h| **h != this)
            .find(|h| {
                live.get(**h)
                    .is_some_and(|since| since.elapsed() >= settled)
            })
            .copied()
    }

    /// Whether `host` was alive at the last reading.
    fn is_alive(&self, host: &str) -> bool {
        let live = self.live.lock().expect("presence lock");
        live.as_ref().is_some_and(|l| l.contains_key(host))
    }

    fn set(&self, alive: &[String]) {
        let mut live = self.live.lock().expect("presence lock");
        let before = live.take().unwrap_or_default();
        *live = Some(
            alive
                .iter()
                .map(|h| {
                    (
                        h.clone(),
                        before.get(h).copied().unwrap_or_else(Instant::now),
                    )
                })
                .collect(),
        );
    }
}

/// Holds this host's presence and reads every host's, every third of a lease, until the
/// mapper stops.
pub(super) async fn keep_presence(host: Arc<Host>) {
    let key = presence_key(&host.cluster.host);
    let every = host.leases.ttl() / 3;
    let mut stopping = host.shared.stopping.subscribe();
    let mut complained = false;
    // Until then, a host found missing is kept alive all the same: after the bucket did not
    // answer (a leader election, longer than a lease), every presence may have lapsed, and a
    // live host gets a lease's time to claim its own again. Without this, the hosts' ranks
    // in a site's order are wrong right after an election, and not the standby but any host
    // may claim a free site.
    let mut unsure_until = Instant::now();
    loop {
        if let Err(e) = sitelog::within(every, hold(&host, &key)).await {
            unsure_until = Instant::now() + host.leases.ttl();
            if !complained {
                tracing::warn!("cluster: this host's presence: {e}");
            }
            complained = true;
        } else {
            complained = false;
        }
        let mut alive = Vec::new();
        for other in &host.cluster.hosts {
            if *other == host.cluster.host {
                continue;
            }
            // Only a lease read and found missing, or a Zenoh token seen to go, says a host is
            // gone: a read that fails (a loaded or electing bucket) keeps what was known.
            let known = host.presence.is_alive(other);
            let other_key = presence_key(other);
            match sitelog::within(every, host.leases.holder(&other_key)).await {
                Ok(Some(_)) => alive.push(other.clone()),
                Ok(None) if known && Instant::now() < unsure_until && !host.tokens.gone(other) => {
                    alive.push(other.clone())
                }
                Ok(None) => {}
                Err(_) => {
                    unsure_until = Instant::now() + host.leases.ttl();
                    if known && !host.tokens.gone(other) {
                        alive.push(other.clone());
                    }
                }
            }
        }
        host.presence.set(&alive);
        tokio::select! {
            _ = tokio::time::sleep(every) => {}
            _ = stopping.changed() => return,
        }
    }
}

/// Claims this host's presence, or renews it; kept with the sites' leases (`held`) so that
/// a graceful stop releases it with them. A presence left by this host's previous run is
/// claimed once it lapses.
async fn hold(host: &Host, key: &str) -> Result<(), sitelog::LogError> {
    let held = host.held.lock().expect("leases lock").get(key).cloned();
    match held {
        Some(mut lease) => {
            let lease = match host.leases.renew(&mut lease).await? {
                true => Some(lease),
                // Lapsed (the bucket electing a leader), or renewed unheard: claimed again.
                false => host.leases.claim_again(key, &host.cluster.host).await?,
            };
            let mut held = host.held.lock().expect("leases lock");
            match lease {
                Some(lease) => held.insert(key.to_owned(), lease),
                None => held.remove(key),
            };
        }
        None => {
            if let Some(lease) = host.leases.claim(key, &host.cluster.host).await? {
                host.held
                    .lock()
                    .expect("leases lock")
                    .insert(key.to_owned(), lease);
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_site_goes_home_only_to_a_live_settled_host_before_this_one() {
        let presence = Presence::default();
        let order = ["h3", "h1", "h2"];
        assert_eq!(presence.live_order(&order, "h2"), None, "unread yet");
        presence.set(&["h1".into()]);
        assert_eq!(presence.live_order(&order, "h2"), Some(vec!["h1", "h2"]));
        // h1 is alive but only just seen: not yet settled.
        assert_eq!(
            presence.home_before(&order, "h2", Duration::from_secs(60)),
            None
        );
        assert_eq!(
            presence.home_before(&order, "h2", Duration::ZERO),
            Some("h1")
        );
        // Nothing before h1 is alive: its sites stay.
        assert_eq!(presence.home_before(&order, "h1", Duration::ZERO), None);
        // h3 comes: first in the order.
        presence.set(&["h1".into(), "h3".into()]);
        assert_eq!(
            presence.home_before(&order, "h1", Duration::ZERO),
            Some("h3")
        );
        // A host gone and back is seen anew.
        std::thread::sleep(Duration::from_millis(20));
        presence.set(&["h3".into()]);
        presence.set(&["h1".into(), "h3".into()]);
        let settled = Duration::from_millis(15);
        assert_eq!(presence.home_before(&order, "h2", settled), Some("h3"));
        assert_eq!(presence.home_before(&["h1", "h2"], "h2", settled), None);
    }
}
