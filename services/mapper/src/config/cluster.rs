//! Cluster mode's configuration (`[cluster]`, docs/cluster.md): this host's place among the
//! mapper hosts, its NATS servers, and the leases' times.

use anyhow::{Result, bail};
use serde::{Deserialize, Serialize};
use sitelog::NatsAccess;
use std::time::Duration;

/// A mapper host's place in the cluster (`[cluster]`); unset: single-machine mode.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ClusterConfig {
    /// This host's name: in the leases, in the site order, the common name of its NATS
    /// certificate.
    pub host: String,
    /// Every mapper host that may own the sites (`fleets`), this one among them: the
    /// rendezvous order of each site is taken over them.
    pub hosts: Vec<String>,
    /// The NATS servers and this host's credentials (`[cluster.nats]`).
    pub nats: NatsAccess,
    /// Copies of each site's log and of the leases: 3, so that one NATS server may be lost.
    pub replicas: usize,
    /// A lease lapses this long after its last renewal (ms): the longest a dead host keeps
    /// its sites. Renewed every third of it.
    pub lease_ttl_ms: u64,
    /// A host whose renewals go unanswered keeps its sites this long past the lease's time
    /// (ms) before it drops them: the leases' bucket electing a leader (4–9 s) does not
    /// drop every site, and a lease that lapsed meanwhile is claimed again, its map kept.
    /// The site's log is what keeps two writers apart (its appends are fenced), so this
    /// costs no acked node; a host cut from NATS acks nothing meanwhile (its appends fail).
    pub renewal_grace_ms: u64,
    /// A free site is claimed by the host of rank r in its order after r times this (ms):
    /// the first host in the order wins unless it is down.
    pub claim_stagger_ms: u64,
    /// A host holding a site hands it back to a host before it in the site's order once
    /// that one has been alive this long (ms): a host started, or back, gets its sites
    /// after it has shown it stays, not at every blink.
    pub hand_back_after_ms: u64,
}

impl Default for ClusterConfig {
    fn default() -> Self {
        ClusterConfig {
            host: String::new(),
            hosts: Vec::new(),
            nats: NatsAccess::default(),
            replicas: 3,
            lease_ttl_ms: 3000,
            renewal_grace_ms: 10_000,
            claim_stagger_ms: 500,
            hand_back_after_ms: 10_000,
        }
    }
}

impl ClusterConfig {
    /// Refuses a configuration that cannot work, saying why.
    pub fn check(&self) -> Result<()> {
        if self.host.is_empty() {
            bail!("[cluster] host: name this mapper host");
        }
        if !self.hosts.contains(&self.host) {
            bail!(
                "[cluster] hosts {:?} must list this host, {:?}",
                self.hosts,
                self.host
            );
        }
        if self.nats.servers.is_empty() {
            bail!("[cluster.nats] servers: list the NATS servers' URLs");
        }
        if self.lease_ttl_ms < 1000 {
            bail!("[cluster] lease_ttl_ms: at least 1000 (a renewal every third of it)");
        }
        if self.replicas == 0 {
            bail!("[cluster] replicas: at least 1 (3 in production)");
        }
        Ok(())
    }

    /// A lease's time to live.
    pub fn ttl(&self) -> Duration {
        Duration::from_millis(self.lease_ttl_ms)
    }

    /// How long a host keeps a site without a renewal answered: the lease and the grace.
    pub fn unrenewed_limit(&self) -> Duration {
        Duration::from_millis(self.lease_ttl_ms + self.renewal_grace_ms)
    }
}
