//! Who owns a site: a lease in a JetStream KV bucket. The bucket keeps each entry for
//! `ttl` only (its `max_age`), so a lease that is not renewed lapses by itself. A host claims a
//! site by writing its key at the revision of the key's last entry, read from the bucket's
//! stream leader (refused while another holds it); renews it with `update` at the revision it
//! holds (refused once another host claimed it after a lapse); and releases it with a delete
//! at that revision on a graceful stop. The lease says who may try to write; the log's fence
//! (`SiteLog::append`) is what stops a writer that lost it and does not know.

use crate::LogError;
use crate::client::passing_refusal;
use async_nats::jetstream::context::Context;
use async_nats::jetstream::kv::{Config, Store, UpdateErrorKind};
use async_nats::jetstream::stream::LastRawMessageErrorKind;
use bytes::Bytes;
use std::time::Duration;

/// The sites' leases, one key per site.
pub struct Leases {
    store: Store,
    ttl: Duration,
}

/// A lease key's last entry.
enum Latest {
    Held {
        host: String,
        revision: u64,
    },
    /// Deleted (a graceful release); claimed again by an update at this revision.
    Released {
        revision: u64,
    },
}

/// The header a KV entry names its operation in (`PUT`, `DEL`, `PURGE`).
const KV_OPERATION: &str = "KV-Operation";

/// How often a claim refused in passing is written (JetStream's 10164), and the wait between.
const CLAIM_TRIES: u32 = 5;
const CLAIM_RETRY: Duration = Duration::from_millis(100);

/// The KV bucket of the sites' leases (and the hosts' presence), as the mapper hosts and
/// the gateways open it.
pub const LEASES_BUCKET: &str = "levelmap_site_leases";

/// A site held by this host, at the revision it last wrote.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Lease {
    /// The site held.
    pub site: String,
    /// This host's name, as written in the lease.
    pub host: String,
    revision: u64,
}

impl Leases {
    /// Opens (or creates) the leases bucket `bucket`, its entries lapsing after `ttl`, kept
    /// on `replicas` servers.
    pub async fn open(
        js: &Context,
        bucket: &str,
        ttl: Duration,
        replicas: usize,
    ) -> Result<Leases, LogError> {
        let config = Config {
            bucket: bucket.to_owned(),
            history: 1,
            max_age: ttl,
            num_replicas: replicas,
            ..Default::default()
        };
        let store = match js.get_key_value(bucket).await {
            Ok(store) => store,
            Err(_) => js
                .create_key_value(config)
                .await
                .map_err(LogError::jetstream)?,
        };
        Ok(Leases { store, ttl })
    }

    /// Opens the leases bucket `bucket` as the mapper hosts made it, to read who holds
    /// what (a gateway): it is not created here, and the leases' time is the bucket's.
    pub async fn existing(js: &Context, bucket: &str) -> Result<Leases, LogError> {
        let store = js
            .get_key_value(bucket)
            .await
            .map_err(LogError::jetstream)?;
        let status = store.status().await.map_err(LogError::jetstream)?;
        Ok(Leases {
            ttl: status.max_age(),
            store,
        })
    }

    /// How long a lease lasts without renewal.
    pub fn ttl(&self) -> Duration {
        self.ttl
    }

    /// Claims `site` for `host`: the lease, or `None` while another host holds it.
    pub async fn claim(&self, site: &str, host: &str) -> Result<Option<Lease>, LogError> {
        let latest = self.latest(site).await?;
        self.claim_if_free(site, host, latest).await
    }

    /// Writes `host` in `site`'s lease if `latest` says the site is free: never written, its
    /// last entry lapsed (revision 0), or released (at the release's revision).
    async fn claim_if_free(
        &self,
        site: &str,
        host: &str,
        latest: Option<Latest>,
    ) -> Result<Option<Lease>, LogError> {
        match latest {
            None => self.write_claim(site, host, 0).await,
            Some(Latest::Released { revision }) => self.write_claim(site, host, revision).await,
            Some(Latest::Held { .. }) => Ok(None),
        }
    }

    /// Claims `site` again for `host`, which held it and whose renewals went unanswered: as
    /// [`Leases::claim`], and also when the lease is held in `host`'s name at a revision
    /// `host` did not hear of (a renewal applied whose answer was lost). `None` while another
    /// host holds it.
    pub async fn claim_again(&self, site: &str, host: &str) -> Result<Option<Lease>, LogError> {
        match self.latest(site).await? {
            Some(Latest::Held {
                host: holder,
                revision,
            }) if holder == host => Ok(Some(Lease {
                site: site.to_owned(),
                host: host.to_owned(),
                revision,
            })),
            latest => self.claim_if_free(site, host, latest).await,
        }
    }

    /// Claims `site` for `host` from `gone`, a holder known to be dead, without waiting for
    /// its lease to lapse: written over `gone`'s entry at its revision, so one host at most
    /// succeeds, and only while `gone` still holds it (or the site is free). `None` while
    /// another host holds it. If `gone` was alive after all, its next renewal is refused and
    /// its next append fenced: it drops the site.
    pub async fn claim_from(
        &self,
        site: &str,
        host: &str,
        gone: &str,
    ) -> Result<Option<Lease>, LogError> {
        match self.latest(site).await? {
            Some(Latest::Held {
                host: holder,
                revision,
            }) if holder == gone => self.write_claim(site, host, revision).await,
            latest => self.claim_if_free(site, host, latest).await,
        }
    }

    /// Writes `host` in `site`'s lease at `expected`, the revision of the key's last entry.
    async fn write_claim(
        &self,
        site: &str,
        host: &str,
        expected: u64,
    ) -> Result<Option<Lease>, LogError> {
        let value = Bytes::from(host.to_owned());
        let mut tries = 1;
        loop {
            match self.store.update(site, value.clone(), expected).await {
                Ok(revision) => {
                    return Ok(Some(Lease {
                        site: site.to_owned(),
                        host: host.to_owned(),
                        revision,
                    }));
                }
                // Another host wrote in between: it holds the site.
                Err(e) if e.kind() == UpdateErrorKind::WrongLastRevision => return Ok(None),
                // Refused without being applied (seen in CI while the hosts renewed): the
                // same write again, at the same revision, cannot claim twice.
                Err(e) if passing_refusal(&e.to_string()) && tries < CLAIM_TRIES => {
                    tries += 1;
                    tokio::time::sleep(CLAIM_RETRY).await;
                }
                Err(e) => return Err(LogError::JetStream(e.to_string())),
            }
        }
    }

    /// The host holding `site`, if any.
    pub async fn holder(&self, site: &str) -> Result<Option<String>, LogError> {
        Ok(match self.latest(site).await? {
            Some(Latest::Held { host, .. }) => Some(host),
            _ => None,
        })
    }

    /// The key's last entry, read from the bucket's stream leader. The KV's own reads go to
    /// any replica (direct get) and may lag: seen in CI, a claim right after a release was
    /// refused as if the site were still held.
    async fn latest(&self, site: &str) -> Result<Option<Latest>, LogError> {
        let subject = format!("{}{}", self.store.prefix, site);
        let message = match self
            .store
            .stream
            .get_last_raw_message_by_subject(&subject)
            .await
        {
            Ok(message) => message,
            Err(e) if e.kind() == LastRawMessageErrorKind::NoMessageFound => return Ok(None),
            Err(e) => return Err(LogError::JetStream(e.to_string())),
        };
        let released = message
            .headers
            .get(KV_OPERATION)
            .is_some_and(|op| op.as_str() != "PUT");
        Ok(Some(if released {
            Latest::Released {
                revision: message.sequence,
            }
        } else {
            Latest::Held {
                host: String::from_utf8_lossy(&message.payload).into_owned(),
                revision: message.sequence,
            }
        }))
    }

    /// Renews `lease` for another `ttl`. `Ok(false)`: it was lost (it lapsed and another host
    /// claimed the site); the host must drop the site at once.
    pub async fn renew(&self, lease: &mut Lease) -> Result<bool, LogError> {
        let value = Bytes::from(lease.host.clone());
        match self.store.update(&lease.site, value, lease.revision).await {
            Ok(revision) => {
                lease.revision = revision;
                Ok(true)
            }
            Err(e) if e.kind() == UpdateErrorKind::WrongLastRevision => Ok(false),
            Err(e) => Err(LogError::JetStream(e.to_string())),
        }
    }

    /// Gives `lease` up (a graceful stop), so the next host need not wait for it to lapse.
    /// Does nothing if another host holds the site by now.
    pub async fn release(&self, lease: Lease) -> Result<(), LogError> {
        match self
            .store
            .delete_expect_revision(&lease.site, Some(lease.revision))
            .await
        {
            Ok(()) => Ok(()),
            // The delete's error kind does not tell a moved-on key from a failure; the
            // server's words do (10071, "wrong last sequence: N").
            Err(e) if e.to_string().contains("wrong last sequence") => Ok(()),
            Err(e) => Err(LogError::JetStream(e.to_string())),
        }
    }
}
