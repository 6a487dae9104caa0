//! The metrics kept with `prometheus-client` (the Prometheus project's Rust client): the
//! latencies as histograms, and the cluster mode's lease and log figures. `/metrics` shows
//! them after the counters of [`super::Metrics`].

use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::{Registry, Unit};
use std::time::Duration;

/// The instruments, registered once.
#[derive(Debug)]
pub struct Instruments {
    /// From a node's arrival at the mapper to its ack.
    pub node_ack: Histogram,
    /// Cluster mode: one batch's append to its site's log, until JetStream acked it.
    pub log_append: Histogram,
    /// Cluster mode: from a site's lease claimed to its map taken by the worker.
    pub takeover: Histogram,
    /// Cluster mode: sites this host owns now.
    pub sites_owned: Gauge,
    /// Cluster mode: of each owned site's log, the copies current (the leader and the
    /// followers caught up), labelled `site`.
    pub log_copies_current: Family<Vec<(String, String)>, Gauge>,
    /// Cluster mode: sites this host took over.
    pub sites_adopted: Counter,
    /// Cluster mode: sites this host dropped (lease lost, append fenced, handed back).
    pub sites_dropped: Counter,
    /// Cluster mode: sites this host handed back to their home host (a live host before it
    /// in the site's order).
    pub sites_handed_back: Counter,
    /// Cluster mode: leases of sites this host owned, claimed again after they lapsed while
    /// the leases' bucket did not answer (the map kept).
    pub leases_reclaimed: Counter,
    /// Cluster mode: leases taken over from a holder whose process was gone (its Zenoh token
    /// went), before they lapsed.
    pub leases_taken_from_gone: Counter,
    /// Cluster mode: appends refused because another writer appended to the site's log.
    pub appends_fenced: Counter,
    /// Cluster mode: records of sites another host owns, read into this host's store as
    /// their standby.
    pub records_followed: Counter,
    /// Cluster mode: records read at a takeover (what the standby had not read yet).
    pub records_taken_over: Counter,
    /// Cluster mode: snapshots of this host's sites put in the object store.
    pub snapshots_shared: Counter,
    /// Cluster mode: snapshots of other hosts' sites taken from the object store into this
    /// host's store.
    pub snapshots_taken_in: Counter,
    /// Cluster mode: clouds of this host's nodes put in the clouds' stream.
    pub clouds_shared: Counter,
    /// Cluster mode: clouds not put (the queue full, or JetStream refused).
    pub clouds_unshared: Counter,
    registry: Registry,
}

impl Default for Instruments {
    fn default() -> Self {
        // 0.5 ms to 8 s in doublings: an fsynced append (~1 ms) up to a leader's election.
        let seconds = || Histogram::new(exponential_buckets(0.0005, 2.0, 15));
        let instruments = Instruments {
            node_ack: seconds(),
            log_append: seconds(),
            // 50 ms to 100 s: a takeover reads a site's whole log when it has no snapshot.
            takeover: Histogram::new(exponential_buckets(0.05, 2.0, 12)),
            sites_owned: Gauge::default(),
            log_copies_current: Family::default(),
            sites_adopted: Counter::default(),
            sites_dropped: Counter::default(),
            sites_handed_back: Counter::default(),
            leases_reclaimed: Counter::default(),
            leases_taken_from_gone: Counter::default(),
            appends_fenced: Counter::default(),
            records_followed: Counter::default(),
            records_taken_over: Counter::default(),
            snapshots_shared: Counter::default(),
            snapshots_taken_in: Counter::default(),
            clouds_shared: Counter::default(),
            clouds_unshared: Counter::default(),
            registry: Registry::default(),
        };
        let mut registry = Registry::default();
        let i = &instruments;
        let timed = [
            (
                "levelmap_node_ack",
                "From a node's arrival to its ack.",
                &i.node_ack,
            ),
            (
                "levelmap_log_append",
                "Cluster mode: a batch's append to its site's log, until JetStream acked it.",
                &i.log_append,
            ),
            (
                "levelmap_site_takeover",
                "Cluster mode: from a site's lease claimed to its map taken.",
                &i.takeover,
            ),
        ];
        for (name, help, histogram) in timed {
            registry.register_with_unit(name, help, Unit::Seconds, histogram.clone());
        }
        registry.register(
            "levelmap_sites_owned",
            "Cluster mode: sites this host owns.",
            i.sites_owned.clone(),
        );
        registry.register(
            "levelmap_site_log_copies_current",
            "Cluster mode: of each owned site's log, the copies current (its leader and the followers caught up); fewer than the replicas: a NATS server down, behind, or out of disk.",
            i.log_copies_current.clone(),
        );
        let counted = [
            (
                "levelmap_sites_adopted",
                "Cluster mode: sites this host took over.",
                &i.sites_adopted,
            ),
            (
                "levelmap_sites_dropped",
                "Cluster mode: sites this host dropped (lease lost, append fenced, handed back).",
                &i.sites_dropped,
            ),
            (
                "levelmap_sites_handed_back",
                "Cluster mode: sites this host handed back to their home host, before it in the site's order.",
                &i.sites_handed_back,
            ),
            (
                "levelmap_leases_reclaimed",
                "Cluster mode: leases of sites this host owned, claimed again after they lapsed while the leases' bucket did not answer (the map kept).",
                &i.leases_reclaimed,
            ),
            (
                "levelmap_leases_taken_from_gone",
                "Cluster mode: leases taken over from a holder whose process was gone (its Zenoh token went), before they lapsed.",
                &i.leases_taken_from_gone,
            ),
            (
                "levelmap_log_appends_fenced",
                "Cluster mode: appends refused because another writer appended to the site's log.",
                &i.appends_fenced,
            ),
            (
                "levelmap_log_records_followed",
                "Cluster mode: records of sites another host owns, read into this host's store as their standby.",
                &i.records_followed,
            ),
            (
                "levelmap_log_records_taken_over",
                "Cluster mode: records read at a takeover (what the standby had not read yet).",
                &i.records_taken_over,
            ),
            (
                "levelmap_snapshots_shared",
                "Cluster mode: snapshots of this host's sites put in the object store.",
                &i.snapshots_shared,
            ),
            (
                "levelmap_snapshots_taken_in",
                "Cluster mode: snapshots of other hosts' sites taken from the object store into this host's store.",
                &i.snapshots_taken_in,
            ),
            (
                "levelmap_clouds_shared",
                "Cluster mode: clouds of this host's nodes put in the clouds' stream.",
                &i.clouds_shared,
            ),
            (
                "levelmap_clouds_unshared",
                "Cluster mode: clouds not put in the clouds' stream (the queue full, or JetStream refused).",
                &i.clouds_unshared,
            ),
        ];
        for (name, help, counter) in counted {
            registry.register(name, help, counter.clone());
        }
        Instruments {
            registry,
            ..instruments
        }
    }
}

impl Instruments {
    /// Observes `elapsed` on `histogram`, in seconds.
    pub fn time(histogram: &Histogram, elapsed: Duration) {
        histogram.observe(elapsed.as_secs_f64());
    }

    /// The instruments in the text format, appended to `out`.
    pub fn encode(&self, out: &mut String) {
        prometheus_client::encoding::text::encode_registry(out, &self.registry)
            .expect("writing to a String");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_text_names_each_instrument_with_its_unit_and_buckets() {
        let i = Instruments::default();
        Instruments::time(&i.log_append, Duration::from_micros(1_500));
        i.sites_adopted.inc();
        i.sites_owned.set(2);
        let park = vec![("site".to_owned(), "park".to_owned())];
        i.log_copies_current.get_or_create(&park).set(2);
        let mut text = String::new();
        i.encode(&mut text);
        let line = |prefix: &str| {
            text.lines()
                .find(|l| l.starts_with(prefix))
                .unwrap_or_else(|| panic!("{prefix} in\n{text}"))
                .to_owned()
        };
        // 1.5 ms: above the 1 ms bucket, within the 2 ms one.
        assert!(line("levelmap_log_append_seconds_bucket{le=\"0.001\"}").ends_with(" 0"));
        assert!(line("levelmap_log_append_seconds_bucket{le=\"0.002\"}").ends_with(" 1"));
        assert!(line("levelmap_log_append_seconds_count").ends_with(" 1"));
        assert!(line("levelmap_node_ack_seconds_count").ends_with(" 0"));
        assert_eq!(
            line("levelmap_sites_adopted_total"),
            "levelmap_sites_adopted_total 1"
        );
        assert_eq!(line("levelmap_sites_owned"), "levelmap_sites_owned 2");
        assert_eq!(
            line("levelmap_site_log_copies_current{"),
            "levelmap_site_log_copies_current{site=\"park\"} 2"
        );
        assert!(
            !text.contains("# EOF"),
            "appended to the other metrics: no EOF"
        );
    }
}
