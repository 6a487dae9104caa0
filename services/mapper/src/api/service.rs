//! The service itself: health, metrics, the OpenAPI document.

use super::Api;
use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use std::fmt::Write as _;
use std::sync::atomic::Ordering;

/// Liveness: 503 once the store failed (a supervisor should restart the mapper).
#[utoipa::path(get, path = "/healthz", tag = "service", responses(
    (status = 200, description = "ok", content_type = "text/plain", body = String),
    (status = 503, description = "the store failed", content_type = "text/plain", body = String),
))]
pub(super) async fn healthz(State(api): State<Api>) -> (StatusCode, &'static str) {
    if api.shared.healthy.load(Ordering::Relaxed) {
        (StatusCode::OK, "ok\n")
    } else {
        (
            StatusCode::SERVICE_UNAVAILABLE,
            "the store failed: restart the mapper\n",
        )
    }
}

/// Prometheus text: accepted, duplicate and rejected messages by reason, map sizes, the
/// HTTP limits' use and refusals.
#[utoipa::path(get, path = "/metrics", tag = "service", responses(
    (status = 200, description = "Prometheus text format 0.0.4", content_type = "text/plain", body = String),
))]
pub(super) async fn metrics(State(api): State<Api>) -> Response {
    let m = &api.shared.metrics;
    let mut out = String::new();
    let counters = [
        (
            "levelmap_nodes_accepted_total",
            "Nodes mapped and stored.",
            &m.nodes_accepted,
        ),
        (
            "levelmap_nodes_duplicate_total",
            "Re-sent nodes taken already (re-acked).",
            &m.nodes_duplicate,
        ),
        (
            "levelmap_odometry_received_total",
            "Live odometry messages taken.",
            &m.odometry_received,
        ),
        ("levelmap_acks_sent_total", "Acks published.", &m.acks_sent),
        (
            "levelmap_optimizations_total",
            "Network optimizations run.",
            &m.optimizations,
        ),
    ];
    for (name, help, value) in counters {
        let _ = writeln!(
            out,
            "# HELP {name} {help}\n# TYPE {name} counter\n{name} {}",
            value.load(Ordering::Relaxed)
        );
    }
    let _ = writeln!(
        out,
        "# HELP levelmap_rejected_total Messages rejected, by topic and reason.\n# TYPE levelmap_rejected_total counter"
    );
    for ((topic, reason), n) in m.rejected.lock().expect("metrics lock").iter() {
        let _ = writeln!(
            out,
            "levelmap_rejected_total{{topic=\"{topic}\",reason=\"{reason}\"}} {n}"
        );
    }
    let fleets = api.shared.fleets.read().expect("views lock").clone();
    let _ = writeln!(
        out,
        "# HELP levelmap_map_nodes Nodes in a fleet's map.\n# TYPE levelmap_map_nodes gauge"
    );
    for (id, v) in &fleets {
        let _ = writeln!(
            out,
            "levelmap_map_nodes{{fleet=\"{id}\"}} {}",
            v.poses.len()
        );
    }
    http_metrics(&api, &mut out);
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], out).into_response()
}

/// This document (OpenAPI 3.1), made from the routes.
#[utoipa::path(get, path = "/api/v1/openapi.json", tag = "service", responses(
    (status = 200, description = "The OpenAPI document", content_type = "application/json", body = Object),
))]
pub(super) async fn openapi(State(api): State<Api>) -> Response {
    let doc = api.openapi.get().cloned().unwrap_or_default();
    ([(header::CONTENT_TYPE, "application/json")], doc).into_response()
}

/// The HTTP limits: what is in use, and what was refused by cause.
fn http_metrics(api: &Api, out: &mut String) {
    let l = &api.limits;
    let _ = writeln!(
        out,
        "# HELP levelmap_http_refused_total Requests answered 503 by a limit: busy (every heavy \
         slot taken), timeout (heavy work not done in time), streams (every event stream slot \
         taken).\n# TYPE levelmap_http_refused_total counter"
    );
    for (reason, n) in [
        ("busy", &l.refused_busy),
        ("timeout", &l.refused_timeout),
        ("streams", &l.refused_streams),
    ] {
        let _ = writeln!(
            out,
            "levelmap_http_refused_total{{reason=\"{reason}\"}} {}",
            n.load(Ordering::Relaxed)
        );
    }
    let _ = writeln!(
        out,
        "# HELP levelmap_http_heavy_running Heavy requests being worked on.\n# TYPE levelmap_http_heavy_running gauge\nlevelmap_http_heavy_running {}",
        l.heavy_running()
    );
    let _ = writeln!(
        out,
        "# HELP levelmap_http_event_streams Event streams open.\n# TYPE levelmap_http_event_streams gauge\nlevelmap_http_event_streams {}",
        l.streams_open()
    );
}
