//! `levelmap gateway`: a stateless HTTP front of a cluster (docs/cluster.md). It holds no
//! map: a request for a site (`/api/v1/fleets/{site}/…`) goes to the mapper host that holds
//! the site's lease, as the leases bucket says at that moment (a robot's live feed, a
//! WebSocket, too); the fleet list is the union of every host's, the event stream every
//! host's merged; anything else (the dashboard, the OpenAPI document) comes from any host
//! that answers. A site without an owner, or whose owner does not answer, is 503 with
//! `Retry-After`. Any number of gateways may run, and any one may be killed.

use anyhow::{Context, Result};
use axum::body::{Body, Bytes};
use axum::extract::{Request, State};
use axum::http::{HeaderValue, Method, StatusCode, header};
use axum::response::{IntoResponse, Response};
use hyper_util::client::legacy::{Client, connect::HttpConnector};
use hyper_util::rt::{TokioExecutor, TokioIo};
use serde::{Deserialize, Serialize};
use sitelog::{LEASES_BUCKET, Leases, NatsAccess};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::OnceCell;

mod metrics;

/// The largest request body the gateway buffers to try it on several hosts.
const MAX_BUFFERED_BODY: usize = 1 << 20;

/// Events waiting for a slow client of the merged event stream; past it the hosts' streams
/// wait (and each host skips what its subscriber missed, as for a direct client).
const EVENTS_QUEUED: usize = 256;

/// A gateway's configuration (deploy/cluster/gateway.toml).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GatewayConfig {
    /// Where the gateway's HTTP listens.
    pub http_listen: String,
    /// Each mapper host's name (its `[cluster] host`) and the address of its HTTP API
    /// (`host:port`).
    pub hosts: BTreeMap<String, String>,
    /// The NATS servers and the gateway's credentials (`[nats]`): it reads the leases.
    pub nats: NatsAccess,
    /// How long a mapper host may take to answer (ms) before the gateway answers 503
    /// with `Retry-After`.
    pub request_timeout_ms: u64,
    /// `Retry-After` (s) of a 503 for a site without an owner: about a lease's time.
    pub retry_after_s: u64,
}

impl Default for GatewayConfig {
    fn default() -> Self {
        GatewayConfig {
            http_listen: "127.0.0.1:8090".into(),
            hosts: BTreeMap::new(),
            nats: NatsAccess::default(),
            request_timeout_ms: 10_000,
            retry_after_s: 3,
        }
    }
}

impl GatewayConfig {
    /// Reads a TOML file, then the `LEVELMAP_…` environment variables; unknown keys are
    /// errors.
    pub fn load(path: Option<&std::path::Path>) -> Result<GatewayConfig> {
        settings::load_toml(path)
    }

    fn check(&self) -> Result<()> {
        anyhow::ensure!(
            !self.hosts.is_empty(),
            "[hosts]: name each mapper host and its HTTP address (h1 = \"10.0.0.1:8080\")"
        );
        anyhow::ensure!(
            !self.nats.servers.is_empty(),
            "[nats] servers: list the NATS servers' URLs"
        );
        Ok(())
    }
}

/// What the gateway's requests share.
struct Gateway {
    config: GatewayConfig,
    js: sitelog::JetStream,
    /// Opened on first use: the gateway serves (503) before NATS answers.
    leases: OnceCell<Leases>,
    client: Client<HttpConnector, Body>,
    /// Who held each site when its lease was last read, and when.
    holders: std::sync::Mutex<std::collections::HashMap<String, (String, Instant)>>,
    /// Its answers, for `/metrics`.
    metrics: metrics::GatewayMetrics,
}

/// A GET goes to the site's holder as read this recently without reading the lease again;
/// an error or a 404 from it reads the lease again (the site may have moved).
const HOLDER_FRESH: Duration = Duration::from_secs(1);

/// A running gateway.
pub struct RunningGateway {
    /// Where its HTTP listens.
    pub http_addr: std::net::SocketAddr,
    stop: tokio::sync::watch::Sender<bool>,
    http: tokio::task::JoinHandle<()>,
}

impl RunningGateway {
    /// Stops accepting and lets open requests finish.
    pub async fn stop(self) -> Result<()> {
        let _ = self.stop.send(true);
        self.http.await?;
        Ok(())
    }
}

/// Starts a gateway: connects to NATS (retried in the background) and listens.
pub async fn start(config: GatewayConfig) -> Result<RunningGateway> {
    config.check()?;
    let js = config.nats.jetstream("levelmap-gateway").await?;
    let mut connector = HttpConnector::new();
    connector.set_connect_timeout(Some(Duration::from_millis(config.request_timeout_ms)));
    let client = Client::builder(TokioExecutor::new()).build(connector);
    let listener = tokio::net::TcpListener::bind(&config.http_listen)
        .await
        .with_context(|| format!("HTTP: cannot listen on {}", config.http_listen))?;
    let http_addr = listener.local_addr()?;
    let gateway = Arc::new(Gateway {
        config,
        js,
        leases: OnceCell::new(),
        client,
        holders: Default::default(),
        metrics: Default::default(),
    });
    let app = axum::Router::new().fallback(route).with_state(gateway);
    let (stop, mut stopping) = tokio::sync::watch::channel(false);
    let http = tokio::spawn(async move {
        let stopped = async move {
            let _ = stopping.wait_for(|s| *s).await;
        };
        let served = axum::serve(listener, app).with_graceful_shutdown(stopped);
        if let Err(e) = served.await {
            tracing::error!("HTTP server: {e}");
        }
    });
    Ok(RunningGateway {
        http_addr,
        stop,
        http,
    })
}

/// Every request: to the site's owner, the union of the fleet lists, or any host; each
/// answer counted and timed by its route.
async fn route(State(gateway): State<Arc<Gateway>>, request: Request) -> Response {
    let path = request.uri().path().to_owned();
    match path.as_str() {
        "/healthz" => return "ok\n".into_response(),
        "/metrics" => {
            let text = gateway.metrics.encode();
            let kind = "application/openmetrics-text; version=1.0.0; charset=utf-8";
            return ([(header::CONTENT_TYPE, kind)], text).into_response();
        }
        _ => {}
    }
    let started = Instant::now();
    let (route, response) = gateway.answer(&path, request).await;
    gateway
        .metrics
        .answered(route, response.status(), started.elapsed());
    response
}

impl Gateway {
    /// The answer to a request of `path`, and its route kind.
    async fn answer(&self, path: &str, request: Request) -> (metrics::Route, Response) {
        if request.method() == Method::GET {
            match path {
                "/api/v1/fleets" => return ("fleets", self.fleet_list(request).await),
                "/api/v1/events" => return ("events", self.events(request).await),
                _ => {}
            }
        }
        match path
            .strip_prefix("/api/v1/fleets/")
            .map(|rest| rest.split('/').next())
        {
            Some(Some(site)) if !site.is_empty() => {
                let site = site.to_owned();
                ("site", self.to_owner(&site, request).await)
            }
            _ => ("other", self.to_any(request).await),
        }
    }
}

impl Gateway {
    fn retry_after(&self, why: &str) -> Response {
        let mut response = answer(StatusCode::SERVICE_UNAVAILABLE, why);
        response.headers_mut().insert(
            header::RETRY_AFTER,
            HeaderValue::from(self.config.retry_after_s),
        );
        response
    }

    async fn leases(&self) -> Result<&Leases, sitelog::LogError> {
        self.leases
            .get_or_try_init(|| Leases::existing(&self.js, LEASES_BUCKET))
            .await
    }

    /// The request, answered by the host that holds `site`'s lease: for a plain GET, the
    /// holder read within [`HOLDER_FRESH`] first (a lease read per request would cost a NATS
    /// round trip each).
    async fn to_owner(&self, site: &str, request: Request) -> Response {
        let plain_get =
            request.method() == Method::GET && !request.headers().contains_key(header::UPGRADE);
        let cached = plain_get.then(|| self.cached_holder(site)).flatten();
        let Some(address) = cached.and_then(|host| self.config.hosts.get(&host)) else {
            return self.to_owner_now(site, request).await;
        };
        let (parts, _) = request.into_parts();
        let again = || Request::from_parts(parts.clone(), Body::empty());
        match self.forward(address, again()).await {
            Ok(response) if response.status() != StatusCode::NOT_FOUND => response,
            _ => {
                self.holders.lock().expect("holders lock").remove(site);
                self.to_owner_now(site, again()).await
            }
        }
    }

    fn cached_holder(&self, site: &str) -> Option<String> {
        let holders = self.holders.lock().expect("holders lock");
        let (host, read) = holders.get(site)?;
        (read.elapsed() < HOLDER_FRESH).then(|| host.clone())
    }

    /// The request, answered by the host that holds `site`'s lease as read now.
    async fn to_owner_now(&self, site: &str, request: Request) -> Response {
        let holder = match self.leases().await {
            Ok(leases) => leases.holder(site).await,
            Err(e) => Err(e),
        };
        let host = match holder {
            Ok(Some(host)) => {
                self.holders
                    .lock()
                    .expect("holders lock")
                    .insert(site.to_owned(), (host.clone(), Instant::now()));
                host
            }
            Ok(None) => {
                return match sitelog::log_exists(&self.js, site).await {
                    Ok(false) => answer(StatusCode::NOT_FOUND, &format!("no site {site}")),
                    _ => self.retry_after(&format!(
                        "site {site} has no owner now: another host takes it over"
                    )),
                };
            }
            Err(e) => return self.retry_after(&format!("the sites' leases cannot be read: {e}")),
        };
        let Some(address) = self.config.hosts.get(&host) else {
            return answer(
                StatusCode::BAD_GATEWAY,
                &format!("site {site} is held by host {host}, which [hosts] does not list"),
            );
        };
        match self.forward(address, request).await {
            Ok(response) => response,
            // A dead owner holds its lease until it lapses; then another host takes over.
            Err(e) => self.retry_after(&format!("site {site}'s owner {host}: {e}")),
        }
    }

    /// The request, answered by the first host that answers.
    async fn to_any(&self, request: Request) -> Response {
        let (parts, body) = request.into_parts();
        let Ok(body) = axum::body::to_bytes(body, MAX_BUFFERED_BODY).await else {
            return answer(StatusCode::PAYLOAD_TOO_LARGE, "request body over 1 MiB");
        };
        let mut errors = Vec::new();
        for (host, address) in &self.config.hosts {
            let request = Request::from_parts(parts.clone(), Body::from(body.clone()));
            match self.forward(address, request).await {
                Ok(response) => return response,
                Err(e) => errors.push(format!("{host}: {e}")),
            }
        }
        self.retry_after(&format!("no mapper host answers ({})", errors.join("; ")))
    }

    /// `/api/v1/fleets`: every host's fleets (the sites it owns) and quarantined fleets.
    async fn fleet_list(&self, request: Request) -> Response {
        let (parts, _) = request.into_parts();
        let (mut fleets, mut quarantined, mut answered) = (Vec::new(), Vec::new(), 0);
        for address in self.config.hosts.values() {
            let request = Request::from_parts(parts.clone(), Body::empty());
            let Ok(response) = self.forward(address, request).await else {
                continue;
            };
            if response.status() != StatusCode::OK {
                return response;
            }
            let Ok(bytes) = axum::body::to_bytes(response.into_body(), MAX_BUFFERED_BODY).await
            else {
                continue;
            };
            let Ok(list) = serde_json::from_slice::<serde_json::Value>(&bytes) else {
                continue;
            };
            answered += 1;
            fleets.extend(list["fleets"].as_array().into_iter().flatten().cloned());
            quarantined.extend(
                list["quarantined"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .cloned(),
            );
        }
        if answered == 0 {
            return self.retry_after("no mapper host answers");
        }
        let key = |v: &serde_json::Value| v.to_string();
        fleets.sort_by_key(key);
        fleets.dedup();
        quarantined.sort_by_key(key);
        quarantined.dedup();
        axum::Json(serde_json::json!({ "fleets": fleets, "quarantined": quarantined }))
            .into_response()
    }

    /// `/api/v1/events`: every host's event stream, merged event by event. It ends when any
    /// host's ends (a host stopped or died): the client's `EventSource` opens it again, on
    /// the hosts as they are then.
    async fn events(&self, request: Request) -> Response {
        let (parts, _) = request.into_parts();
        let (merged, events) = tokio::sync::mpsc::channel::<Option<Bytes>>(EVENTS_QUEUED);
        let mut opened = 0;
        for address in self.config.hosts.values() {
            let request = Request::from_parts(parts.clone(), Body::empty());
            match self.forward(address, request).await {
                Ok(response) if response.status() == StatusCode::OK => {
                    opened += 1;
                    tokio::spawn(pass_events(response.into_body(), merged.clone()));
                }
                _ => {}
            }
        }
        drop(merged);
        if opened == 0 {
            return self.retry_after("no mapper host answers");
        }
        let stream = futures_util::stream::unfold(events, |mut events| async move {
            let event = events.recv().await.flatten()?;
            Some((Ok::<_, std::convert::Infallible>(event), events))
        });
        (
            [
                (header::CONTENT_TYPE, "text/event-stream"),
                (header::CACHE_CONTROL, "no-cache"),
            ],
            Body::from_stream(stream),
        )
            .into_response()
    }

    /// Sends `request` to the mapper host at `address`; its answer, or why there is none.
    async fn forward(&self, address: &str, request: Request) -> Result<Response, String> {
        let (mut parts, body) = request.into_parts();
        let path = parts
            .uri
            .path_and_query()
            .map_or("/", |p| p.as_str())
            .to_owned();
        parts.uri = format!("http://{address}{path}")
            .parse()
            .map_err(|e| format!("{address}: {e}"))?;
        // The client names the host it connects to.
        parts.headers.remove(header::HOST);
        let mut request = Request::from_parts(parts, body);
        // A WebSocket (a robot's live feed): once both sides switched protocols, the bytes
        // are copied both ways until either closes.
        let upgrade = request
            .headers()
            .contains_key(header::UPGRADE)
            .then(|| hyper::upgrade::on(&mut request));
        let timeout = Duration::from_millis(self.config.request_timeout_ms);
        let sent = self.client.request(request);
        let mut response = match tokio::time::timeout(timeout, sent).await {
            Ok(Ok(response)) => response,
            Ok(Err(e)) => return Err(format!("{address}: {e}")),
            Err(_) => return Err(format!("{address}: no answer within {timeout:?}")),
        };
        if let Some(client_side) = upgrade
            && response.status() == StatusCode::SWITCHING_PROTOCOLS
        {
            let host_side = hyper::upgrade::on(&mut response);
            tokio::spawn(async move {
                let (Ok(client_side), Ok(host_side)) = tokio::join!(client_side, host_side) else {
                    return;
                };
                let (mut client_side, mut host_side) =
                    (TokioIo::new(client_side), TokioIo::new(host_side));
                let _ = tokio::io::copy_bidirectional(&mut client_side, &mut host_side).await;
            });
        }
        Ok(response.map(Body::new))
    }
}

/// One host's event stream into `merged`, whole events at a time (an event ends with a
/// blank line); `None` when it ends.
async fn pass_events(body: Body, merged: tokio::sync::mpsc::Sender<Option<Bytes>>) {
    use futures_util::StreamExt;
    let mut data = body.into_data_stream();
    let mut pending: Vec<u8> = Vec::new();
    while let Some(Ok(chunk)) = data.next().await {
        pending.extend_from_slice(&chunk);
        while let Some(end) = pending.windows(2).position(|w| w == b"\n\n") {
            let event: Vec<u8> = pending.drain(..end + 2).collect();
            if merged.send(Some(Bytes::from(event))).await.is_err() {
                return;
            }
        }
    }
    let _ = merged.send(None).await;
}

/// A plain-text answer.
fn answer(status: StatusCode, text: &str) -> Response {
    (status, format!("{text}\n")).into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every table of the config, the unset ones too, refuses a misspelt key, naming the
    /// file, the line and the keys expected (a typo must not silently become a default).
    #[test]
    fn a_misspelt_key_in_any_table_is_refused_with_its_file_and_line() {
        settings::typos::assert_every_table_refuses::<GatewayConfig, _>(&[], 1, |path| {
            GatewayConfig::load(Some(path))
        });
    }

    #[test]
    fn a_gateway_without_hosts_or_servers_is_refused_saying_what_to_set() {
        let config = GatewayConfig::default();
        let e = config.check().unwrap_err().to_string();
        assert!(e.contains("[hosts]"), "{e}");
        let config = GatewayConfig {
            hosts: [("h1".to_owned(), "127.0.0.1:8080".to_owned())].into(),
            ..GatewayConfig::default()
        };
        let e = config.check().unwrap_err().to_string();
        assert!(e.contains("[nats] servers"), "{e}");
    }

    #[test]
    fn the_deployed_gateway_file_is_whole_and_valid() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../deploy/cluster/gateway.toml");
        let file: GatewayConfig = settings::load_toml_with(Some(&path), []).unwrap();
        file.check().unwrap();
        assert_eq!(file.hosts.len(), 3);
        assert!(
            file.nats.cert.is_some(),
            "a gateway has its own certificate"
        );
    }
}
