//! The router as a whole, requests sent straight into it: the document, the read token,
//! CORS and the event streams' cap.

use super::*;
use crate::config::{CorsOrigin, HttpConfig};
use axum::body::Body;
use axum::http::{Method, Request};
use std::num::NonZeroUsize;
use std::sync::atomic::{AtomicUsize, Ordering};
use tower::ServiceExt;

/// Every route the router serves is in the document, and nothing else: both come from
/// [`super::open_routes`] and [`super::guarded_routes`]; this checks the document's side
/// against the lists of handlers.
#[test]
fn the_document_lists_every_route_with_its_parameters() {
    let doc: serde_json::Value = serde_json::from_str(&super::openapi_json()).unwrap();
    let paths = doc["paths"].as_object().unwrap();
    let mut listed: Vec<&str> = paths.keys().map(String::as_str).collect();
    listed.sort_unstable();
    assert_eq!(listed.len(), 36, "{listed:?}");
    // Operation ids are the handlers' names: two modules' `summary` would clash.
    let mut ids = std::collections::HashSet::new();
    for (path, item) in paths {
        for (method, op) in item.as_object().unwrap() {
            let id = op["operationId"].as_str().unwrap_or_default();
            assert!(
                ids.insert(id.to_owned()),
                "{method} {path}: operationId {id} twice"
            );
            // Each {param} of the path is a documented path parameter.
            for name in path.split('{').skip(1).map(|s| &s[..s.find('}').unwrap()]) {
                let declared = op["parameters"]
                    .as_array()
                    .is_some_and(|ps| ps.iter().any(|p| p["name"] == name && p["in"] == "path"));
                assert!(
                    declared,
                    "{method} {path}: path parameter {name} undocumented"
                );
            }
            // 201 for what a POST makes, 204 for a DELETE.
            let success = ["200", "201", "204"];
            assert!(
                success.iter().any(|s| op["responses"][s].is_object()),
                "{method} {path}: no 2xx"
            );
        }
    }
}

/// The bearer scheme is declared; every `/api` route but the token check may need it and may
/// answer 401; the open routes do neither.
#[test]
fn the_document_declares_the_bearer_token_where_it_is_needed() {
    let doc: serde_json::Value = serde_json::from_str(&super::openapi_json()).unwrap();
    let scheme = &doc["components"]["securitySchemes"]["bearer"];
    assert_eq!(
        (scheme["type"].as_str(), scheme["scheme"].as_str()),
        (Some("http"), Some("bearer"))
    );
    for (path, item) in doc["paths"].as_object().unwrap() {
        for (method, op) in item.as_object().unwrap() {
            let bearer = op["security"]
                .as_array()
                .is_some_and(|s| s.iter().any(|r| r.get("bearer").is_some()));
            let guarded = path.starts_with("/api/") && path != "/api/v1/auth";
            assert_eq!(
                op["responses"]["401"].is_object(),
                guarded,
                "{method} {path}: 401"
            );
            assert_eq!(
                bearer,
                path.starts_with("/api/"),
                "{method} {path}: security"
            );
        }
    }
}

/// A router over an empty mapper (no worker: an operator request finds it stopped).
fn app(config: &MapperConfig) -> Router {
    app_over(config, Arc::new(Shared::new(config.token.clone(), 0)))
}

/// [`app`] over views the test holds.
fn app_over(config: &MapperConfig, shared: Arc<Shared>) -> Router {
    static N: AtomicUsize = AtomicUsize::new(0);
    let path = std::env::temp_dir().join(format!(
        "levelmap-api-{}-{}.redb",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    let store = Arc::new(Store::open(&path).unwrap());
    // The file can go: the open database keeps what it needs.
    std::fs::remove_file(&path).ok();
    let maps = Arc::new(crate::localization::MapCache::new(
        &config.localization,
        config.max_range_m,
    ));
    router(
        shared,
        mpsc::sync_channel(1).0,
        store,
        maps,
        Arc::new(crate::blobs::NotShared),
        config,
    )
}

fn tokens() -> MapperConfig {
    MapperConfig {
        token: "w-token".into(),
        read_token: "r-token".into(),
        ..MapperConfig::default()
    }
}

async fn send(app: &Router, method: Method, path: &str, headers: &[(&str, &str)]) -> Response {
    let mut request = Request::builder().method(method).uri(path);
    for (k, v) in headers {
        request = request.header(*k, *v);
    }
    app.clone()
        .oneshot(request.body(Body::empty()).unwrap())
        .await
        .unwrap()
}

async fn get(app: &Router, path: &str, token: Option<&str>) -> Response {
    let auth = token.map(|t| format!("Bearer {t}"));
    let headers: Vec<(&str, &str)> = auth.iter().map(|a| ("authorization", a.as_str())).collect();
    send(app, Method::GET, path, &headers).await
}

async fn text(r: Response) -> String {
    let bytes = axum::body::to_bytes(r.into_body(), 1 << 20).await.unwrap();
    String::from_utf8_lossy(&bytes).into_owned()
}

#[tokio::test]
async fn a_read_token_guards_every_api_route_but_the_token_check() {
    let app = app(&tokens());
    let doc: serde_json::Value = serde_json::from_str(&super::openapi_json()).unwrap();
    for (template, item) in doc["paths"].as_object().unwrap() {
        let path = template
            .replace("{fleet}", "park")
            .replace("{robot}", "r0")
            .replace("{node}", "0")
            .replace("{version}", "1")
            .replace("{file}", "app.js");
        let method = if item.get("post").is_some() {
            Method::POST
        } else {
            Method::GET
        };
        let r = send(&app, method.clone(), &path, &[]).await;
        let guarded = template.starts_with("/api/") && template != "/api/v1/auth";
        if guarded {
            assert_eq!(r.status(), 401, "{method} {path}");
            assert_eq!(
                r.headers()["www-authenticate"],
                "Bearer realm=\"levelmap\"",
                "{path}"
            );
        } else {
            assert_eq!(r.status(), 200, "{method} {path} is open");
        }
    }
    // Either token reads (an empty mapper: no fleets yet); another does not.
    for token in ["r-token", "w-token"] {
        let r = get(&app, "/api/v1/fleets", Some(token)).await;
        assert_eq!(r.status(), 200, "{token}");
    }
    let r = get(&app, "/api/v1/fleets", Some("r-tokenX")).await;
    assert_eq!(r.status(), 401);
    // Writing needs the write token: the read token is refused, the write token passes (to a
    // mapper with no worker here, so it is told the mapper is stopping).
    let optimize = "/api/v1/fleets/park/optimize";
    let post = |t: &'static str| {
        let app = app.clone();
        async move {
            let auth = format!("Bearer {t}");
            send(&app, Method::POST, optimize, &[("authorization", &auth)]).await
        }
    };
    let r = post("r-token").await;
    assert_eq!(r.status(), 403);
    assert!(text(r).await.contains("only reads"));
    assert_eq!(post("w-token").await.status(), 503);
    // The token check tells a page what it needs without a 401.
    let auth: serde_json::Value =
        serde_json::from_str(&text(get(&app, "/api/v1/auth", None).await).await).unwrap();
    assert_eq!(
        (&auth["read_required"], &auth["read"], &auth["authorized"]),
        (&true.into(), &false.into(), &false.into())
    );
    let auth: serde_json::Value =
        serde_json::from_str(&text(get(&app, "/api/v1/auth", Some("r-token")).await).await)
            .unwrap();
    assert_eq!(
        (&auth["read"], &auth["authorized"]),
        (&true.into(), &false.into())
    );
}

#[tokio::test]
async fn without_a_read_token_reading_is_open() {
    let app = app(&MapperConfig::default());
    assert_eq!(get(&app, "/api/v1/fleets", None).await.status(), 200);
    assert_eq!(get(&app, "/api/v1/fleets", Some("any")).await.status(), 200);
    let auth = text(get(&app, "/api/v1/auth", None).await).await;
    assert!(
        auth.contains("\"read_required\":false") && auth.contains("\"read\":true"),
        "{auth}"
    );
}

#[tokio::test]
async fn cors_answers_the_listed_origins_only() {
    let origin = "https://ops.example.org";
    let mut config = tokens();
    config.http.cors_origins = vec![CorsOrigin::try_from(origin.to_owned()).unwrap()];
    let app = app(&config);
    // A preflight carries no token: answered before the token check.
    let preflight = [
        ("origin", origin),
        ("access-control-request-method", "GET"),
        ("access-control-request-headers", "authorization"),
    ];
    let r = send(&app, Method::OPTIONS, "/api/v1/fleets", &preflight).await;
    assert_eq!(r.status(), 200);
    let h = r.headers();
    assert_eq!(h["access-control-allow-origin"], origin);
    assert!(
        h["access-control-allow-headers"]
            .to_str()
            .unwrap()
            .contains("authorization")
    );
    assert!(
        h["access-control-allow-methods"]
            .to_str()
            .unwrap()
            .contains("GET")
    );
    let auth = [("origin", origin), ("authorization", "Bearer r-token")];
    let r = send(&app, Method::GET, "/api/v1/fleets", &auth).await;
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["access-control-allow-origin"], origin);
    // A 401 carries it too, so the page can read why.
    let r = send(&app, Method::GET, "/api/v1/fleets", &[("origin", origin)]).await;
    assert_eq!(r.status(), 401);
    assert_eq!(r.headers()["access-control-allow-origin"], origin);
    let other = [
        ("origin", "https://elsewhere.example"),
        ("authorization", "Bearer r-token"),
    ];
    let r = send(&app, Method::GET, "/api/v1/fleets", &other).await;
    assert!(r.headers().get("access-control-allow-origin").is_none());
}

#[tokio::test]
async fn no_cors_headers_by_default() {
    let app = app(&MapperConfig::default());
    let origin = [("origin", "https://ops.example.org")];
    let r = send(&app, Method::GET, "/api/v1/fleets", &origin).await;
    assert_eq!(r.status(), 200);
    assert!(
        r.headers()
            .keys()
            .all(|k| !k.as_str().starts_with("access-control-"))
    );
    let r = send(&app, Method::OPTIONS, "/api/v1/fleets", &origin).await;
    assert_eq!(r.status(), 405);
}

#[tokio::test]
async fn event_streams_are_capped_and_a_closed_one_frees_its_place() {
    let mut config = tokens();
    config.http = HttpConfig {
        event_streams: NonZeroUsize::new(2).unwrap(),
        ..HttpConfig::default()
    };
    let app = app(&config);
    let events = "/api/v1/events";
    let first = get(&app, events, Some("r-token")).await;
    let second = get(&app, events, Some("w-token")).await;
    assert_eq!(
        (first.status().as_u16(), second.status().as_u16()),
        (200, 200)
    );
    let third = get(&app, events, Some("r-token")).await;
    assert_eq!(third.status(), 503);
    assert_eq!(third.headers()["retry-after"], "1");
    assert!(text(third).await.contains("2 event streams"));
    // A client that goes away drops its stream.
    drop(first);
    assert_eq!(get(&app, events, Some("r-token")).await.status(), 200);
    let metrics = text(get(&app, "/metrics", None).await).await;
    assert!(
        metrics.contains("levelmap_http_refused_total{reason=\"streams\"} 1"),
        "{metrics}"
    );
}

/// Every metric the shipped alert rules name is on `/metrics` (the cluster's too: their
/// instruments are always registered), and the faults they watch show there.
#[tokio::test]
async fn the_alert_rules_metrics_are_served_and_show_the_faults() {
    let rules = include_str!("../../../../deploy/prometheus/levelmap-alerts.yml");
    let config = MapperConfig {
        fleets: vec!["park".into(), "campus".into()],
        ..MapperConfig::default()
    };
    let shared = Arc::new(Shared::new(String::new(), 0));
    *shared.store_fault.write().unwrap() = Some("No space left on device".into());
    let why = "store: node 1 of fleet campus is unreadable".to_owned();
    shared
        .quarantined
        .write()
        .unwrap()
        .insert("campus".into(), why);
    // A cluster host's site log with a copy down (a family shows once it has a member).
    let site = vec![("site".to_owned(), "park".to_owned())];
    shared
        .instruments
        .log_copies_current
        .get_or_create(&site)
        .set(2);
    let app = app_over(&config, shared);
    let metrics = text(get(&app, "/metrics", None).await).await;
    let mut named: Vec<&str> = rules
        .split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .filter(|w| w.starts_with("levelmap_"))
        .collect();
    named.sort_unstable();
    named.dedup();
    assert!(named.len() >= 6, "{named:?}");
    for name in named {
        let family = name.strip_suffix("_total").unwrap_or(name);
        let typed = |n: &str| {
            metrics
                .lines()
                .any(|l| l.starts_with(&format!("# TYPE {n} ")))
        };
        assert!(
            typed(name) || typed(family),
            "{name} is not on /metrics:\n{metrics}"
        );
    }
    for line in [
        "levelmap_store_fault 1",
        "levelmap_fleets_served 2",
        "levelmap_fleets_quarantined 1",
        "levelmap_fleet_quarantined{fleet=\"campus\"} 1",
        "levelmap_site_log_copies_current{site=\"park\"} 2",
    ] {
        assert!(metrics.lines().any(|l| l == line), "{line}:\n{metrics}");
    }
    // The text format: every line a comment, a sample or empty, none indented.
    for line in metrics.lines() {
        assert!(!line.starts_with(char::is_whitespace), "{line:?}");
    }
}
