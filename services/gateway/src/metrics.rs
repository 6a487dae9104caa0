//! The gateway's own `/metrics` (Prometheus text, `prometheus-client`): its answers by route
//! and status, and how long they took. The map's figures are each mapper host's.

use axum::http::StatusCode;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::{Registry, Unit};
use std::time::Duration;

/// A request's route kind: `site` (to the site's owner), `fleets` (the union of every host's
/// list), `events` (every host's stream merged) or `other` (any host that answers).
pub(crate) type Route = &'static str;

type Labels = Vec<(&'static str, String)>;

/// The gateway's instruments.
pub(crate) struct GatewayMetrics {
    answers: Family<Labels, Counter>,
    seconds: Family<Labels, Histogram, fn() -> Histogram>,
    registry: Registry,
}

fn histogram() -> Histogram {
    // 1 ms to 16 s in doublings: a forwarded GET up to the request timeout.
    Histogram::new(exponential_buckets(0.001, 2.0, 15))
}

impl Default for GatewayMetrics {
    fn default() -> Self {
        let answers = Family::<Labels, Counter>::default();
        let seconds = Family::<Labels, Histogram, fn() -> Histogram>::new_with_constructor(
            histogram as fn() -> Histogram,
        );
        let mut registry = Registry::default();
        registry.register(
            "levelmap_gateway_answers",
            "Answers by route (site, fleets, events, other) and status code; a site's 503s are a site without an owner, an owner that does not answer, or leases that cannot be read.",
            answers.clone(),
        );
        registry.register_with_unit(
            "levelmap_gateway_answer",
            "From a request's arrival to its answer's head, by route.",
            Unit::Seconds,
            seconds.clone(),
        );
        GatewayMetrics {
            answers,
            seconds,
            registry,
        }
    }
}

impl GatewayMetrics {
    /// Counts an answer of `route` with `status`, given in `elapsed`.
    pub(crate) fn answered(&self, route: Route, status: StatusCode, elapsed: Duration) {
        let labels = vec![
            ("route", route.to_owned()),
            ("code", status.as_u16().to_string()),
        ];
        self.answers.get_or_create(&labels).inc();
        let route = vec![("route", route.to_owned())];
        self.seconds
            .get_or_create(&route)
            .observe(elapsed.as_secs_f64());
    }

    /// The text format.
    pub(crate) fn encode(&self) -> String {
        let mut out = String::new();
        prometheus_client::encoding::text::encode(&mut out, &self.registry)
            .expect("writing to a String");
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn answers_are_counted_by_route_and_status_and_timed_by_route() {
        let m = GatewayMetrics::default();
        m.answered("site", StatusCode::OK, Duration::from_millis(3));
        m.answered(
            "site",
            StatusCode::SERVICE_UNAVAILABLE,
            Duration::from_millis(1),
        );
        m.answered(
            "site",
            StatusCode::SERVICE_UNAVAILABLE,
            Duration::from_millis(1),
        );
        let text = m.encode();
        let line = |start: &str| {
            text.lines()
                .find(|l| l.starts_with(start))
                .unwrap_or_else(|| panic!("{start} in\n{text}"))
                .to_owned()
        };
        assert!(line("levelmap_gateway_answers_total{").contains("route=\"site\""));
        let unavailable = text
            .lines()
            .find(|l| l.starts_with("levelmap_gateway_answers_total") && l.contains("\"503\""))
            .expect("the 503s");
        assert!(unavailable.ends_with(" 2"), "{unavailable}");
        assert!(
            line("levelmap_gateway_answer_seconds_count{").ends_with(" 3"),
            "{text}"
        );
        assert!(text.contains("# EOF"), "{text}");
    }
}
