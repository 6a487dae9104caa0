//! The service itself: health, metrics, the OpenAPI document.

use super::Api;
use axum::Json;
use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::sync::atomic::Ordering;
use utoipa::ToSchema;

/// The mapper's health: `ok`, or `degraded` with what is wrong.
#[derive(Serialize, ToSchema)]
pub(super) struct Health {
    /// `ok`, or `degraded`: the store cannot commit, or a fleet is quarantined.
    status: &'static str,
    /// Why the store cannot commit, while it cannot: nodes are not acked, and the routes
    /// that need the store answer 503; the mapper resumes by itself once a commit succeeds.
    store: Option<String>,
    /// Fleets whose stored map did not replay at start, each with why: their routes answer
    /// 503 and their nodes are not taken; the other fleets run.
    quarantined: BTreeMap<String, String>,
}

/// Health: 503 (with `Retry-After`) while the store cannot commit, 200 otherwise; a
/// quarantined fleet makes it `degraded` but not 503, as the other fleets are served and a
/// restart would not mend it.
#[utoipa::path(get, path = "/healthz", tag = "service", responses(
    (status = 200, description = "ok, or degraded by a quarantined fleet", body = Health),
    (status = 503, description = "the store cannot commit", body = Health),
))]
pub(super) async fn healthz(State(api): State<Api>) -> Response {
    let store = api.shared.store_fault();
    let quarantined = api.shared.quarantined_fleets();
    let (code, retry) = match store {
        Some(_) => {
            let retry = [(header::RETRY_AFTER, super::faults::RETRY_AFTER_S)];
            (StatusCode::SERVICE_UNAVAILABLE, Some(retry))
        }
        None => (StatusCode::OK, None),
    };
    let status = if code == StatusCode::OK && quarantined.is_empty() {
        "ok"
    } else {
        "degraded"
    };
    let health = Health {
        status,
        store,
        quarantined,
    };
    (code, retry, Json(health)).into_response()
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
            "levelmap_nodes_received_total",
            "Node messages received from robots (re-sends included), before any check.",
            &m.nodes_received,
        ),
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
            "levelmap_nodes_localized_total",
            "Nodes of localizing robots found on a map version (not mapped).",
            &m.nodes_localized,
        ),
        (
            "levelmap_nodes_passed_total",
            "Nodes of mapping robots passed over covered ground (located, not mapped).",
            &m.nodes_passed,
        ),
        (
            "levelmap_clouds_pruned_total",
            "3D clouds dropped by the retention policy ([clouds]).",
            &m.clouds_pruned,
        ),
        (
            "levelmap_localizations_sent_total",
            "Localizations published to localizing robots.",
            &m.localizations_sent,
        ),
        (
            "levelmap_odometry_received_total",
            "Live odometry messages taken.",
            &m.odometry_received,
        ),
        ("levelmap_acks_sent_total", "Acks published.", &m.acks_sent),
        (
            "levelmap_fleets_rebuilt_total",
            "Fleets rebuilt from their nodes at start (stored by another mapping version).",
            &m.fleets_rebuilt,
        ),
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
    fault_metrics(&api, &mut out);
    http_metrics(&api, &mut out);
    api.shared.instruments.encode(&mut out);
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

/// What an operator must act on (deploy/prometheus/levelmap-alerts.yml): a store that does
/// not commit, quarantined fleets, and the fleets this mapper serves.
fn fault_metrics(api: &Api, out: &mut String) {
    let store_fault = u8::from(api.shared.store_fault().is_some());
    let quarantined = api.shared.quarantined_fleets();
    let gauges = [
        (
            "levelmap_store_fault",
            "1 while the store does not commit (a full disk, a failed write): nodes wait unacked in the robots' outboxes.",
            u64::from(store_fault),
        ),
        (
            "levelmap_fleets_served",
            "Fleets (sites) this mapper serves ([fleets]).",
            api.served.len() as u64,
        ),
        (
            "levelmap_fleets_quarantined",
            "Fleets whose stored rows cannot be read or mapped: their routes answer 503 and their robots' nodes wait.",
            quarantined.len() as u64,
        ),
    ];
    for (name, help, value) in gauges {
        let _ = writeln!(
            out,
            "# HELP {name} {help}\n# TYPE {name} gauge\n{name} {value}"
        );
    }
    let name = "levelmap_fleet_quarantined";
    let _ = writeln!(
        out,
        "# HELP {name} 1 for each quarantined fleet.\n# TYPE {name} gauge"
    );
    for fleet in quarantined.keys() {
        let _ = writeln!(out, "{name}{{fleet=\"{fleet}\"}} 1");
    }
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
