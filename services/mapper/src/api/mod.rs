//! The HTTP API (`/api/v1`, JSON), one module per resource: thin handlers over the current
//! fleet views that call the domain (`slam`, `graphio`) for any work. Every route is
//! registered through [`utoipa_axum`], so the OpenAPI document served at
//! `/api/v1/openapi.json` is made from the same lists as the router. Routes are open
//! (`open_routes`) or guarded by the read token (`guarded_routes`); heavy handlers run their
//! work through `limits`; `access` holds the tokens and CORS.

mod access;
mod backup;
mod changes;
mod events;
mod faults;
mod fleets;
mod geo;
mod graph;
mod limits;
mod live;
mod localize;
mod map;
mod nodes;
mod service;
mod versions;
mod web;
mod window;

use crate::blobs::Blobs;
use crate::config::MapperConfig;
use crate::inbox::Work;
use crate::store::Store;
use crate::views::Shared;
use axum::Router;
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use fleetmap::FleetView;
use fleetmap::marginals::Marginals;
use std::sync::{Arc, OnceLock, mpsc};
use utoipa::OpenApi;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

pub use faults::Degraded;
pub use web::WEB_DIR_ENV;

/// What every handler shares.
#[derive(Clone)]
struct Api {
    shared: Arc<Shared>,
    work: mpsc::SyncSender<Work>,
    /// Covariance queries: one optimizer per fleet, its factorization kept.
    marginals: Arc<Marginals>,
    /// Read for the nodes' clouds, which no view holds.
    store: Arc<Store>,
    /// The OpenAPI document, made once from the routes.
    openapi: Arc<OnceLock<String>>,
    /// The read and write tokens.
    tokens: Arc<access::Tokens>,
    /// Heavy requests and event streams at once.
    limits: Arc<limits::Limits>,
    /// The map's tiles, for windows around robots.
    tiles: Arc<fleetmap::tiles::TileCache>,
    /// The fleets this mapper serves.
    served: Arc<[String]>,
    /// Versions a fleet keeps at most (`[versions] max_versions`).
    max_versions: usize,
    /// Versions' localization maps, shared with the worker.
    maps: Arc<crate::localization::MapCache>,
    /// Held while a change of a site's versions or modes is checked and journaled: one at
    /// a time, so a version's number is given once and a check holds until its change is
    /// durable.
    changes_lock: Arc<tokio::sync::Mutex<()>>,
    /// The base map the dashboard may draw (`[http.base_map]`).
    base_map: Option<Arc<crate::config::BaseMap>>,
    /// The version files and clouds shared beyond this host's store ([`crate::blobs`]).
    blobs: Arc<dyn Blobs>,
    /// Backups of the store, one at a time.
    backups: Arc<backup::Backups>,
}

/// An error answer: its status and a one-line reason as plain text.
#[derive(Debug)]
pub enum ApiError {
    /// 400: a parameter that cannot be read.
    BadRequest(String),
    /// 401: no valid bearer token (answered with `WWW-Authenticate: Bearer`).
    Unauthorized(String),
    /// 403: write routes are off (no token configured), or the token only reads.
    Forbidden(String),
    /// 404: no such fleet, robot, node, version or file.
    NotFound(String),
    /// 409: the request conflicts with what is stored (a fleet keeping its most versions).
    Conflict(String),
    /// 413: a body over its bound.
    TooLarge(String),
    /// 422: the map cannot answer this (a grid too large, a network that cannot be solved).
    Unprocessable(String),
    /// 503: the mapper is stopping.
    Unavailable(String),
    /// 503 as JSON: a quarantined fleet, or a store that cannot commit.
    Degraded(Degraded),
    /// 503 with `Retry-After: 1`: a limit is reached (heavy requests, their time, streams).
    Busy(String),
    /// 500: a fault of the server (the store, a task).
    Internal(String),
}

impl ApiError {
    fn internal(e: impl std::fmt::Display) -> ApiError {
        ApiError::Internal(e.to_string())
    }

    fn status(&self) -> StatusCode {
        match self {
            ApiError::BadRequest(_) => StatusCode::BAD_REQUEST,
            ApiError::Unauthorized(_) => StatusCode::UNAUTHORIZED,
            ApiError::Forbidden(_) => StatusCode::FORBIDDEN,
            ApiError::NotFound(_) => StatusCode::NOT_FOUND,
            ApiError::Conflict(_) => StatusCode::CONFLICT,
            ApiError::TooLarge(_) => StatusCode::PAYLOAD_TOO_LARGE,
            ApiError::Unprocessable(_) => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::Unavailable(_) | ApiError::Degraded(_) | ApiError::Busy(_) => {
                StatusCode::SERVICE_UNAVAILABLE
            }
            ApiError::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    fn reason(&self) -> &str {
        match self {
            ApiError::BadRequest(r)
            | ApiError::Unauthorized(r)
            | ApiError::Forbidden(r)
            | ApiError::NotFound(r)
            | ApiError::Conflict(r)
            | ApiError::TooLarge(r)
            | ApiError::Unprocessable(r)
            | ApiError::Unavailable(r)
            | ApiError::Busy(r)
            | ApiError::Internal(r) => r,
            ApiError::Degraded(d) => &d.reason,
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        if let ApiError::Degraded(d) = &self {
            let retry = d
                .retry_after_s
                .map(|s| [(axum::http::header::RETRY_AFTER, s)]);
            return (self.status(), retry, axum::Json(d)).into_response();
        }
        let mut response = (self.status(), self.reason().to_owned()).into_response();
        let extra = match self {
            ApiError::Unauthorized(_) => {
                Some((header::WWW_AUTHENTICATE, "Bearer realm=\"levelmap\""))
            }
            ApiError::Busy(_) => Some((header::RETRY_AFTER, "1")),
            _ => None,
        };
        if let Some((name, value)) = extra {
            response
                .headers_mut()
                .insert(name, header::HeaderValue::from_static(value));
        }
        response
    }
}

type Reply<T = Response> = Result<T, ApiError>;

impl Api {
    /// The fleet's current view; 503 for a quarantined fleet.
    fn view(&self, fleet: &str) -> Reply<Arc<FleetView>> {
        self.available(fleet)?;
        self.shared.fleet(fleet).ok_or_else(|| {
            ApiError::NotFound(format!("no fleet {fleet:?} (no node received yet?)"))
        })
    }
}

impl Api {
    /// 503 with the reason when the fleet is quarantined.
    fn available(&self, fleet: &str) -> Reply<()> {
        match self.shared.quarantine(fleet) {
            Some(reason) => Err(Degraded::quarantined(fleet, reason)),
            None => Ok(()),
        }
    }

    /// 503 for a store that is closed after a failed commit; 500 for any other failure.
    fn store_error(&self, e: crate::store::StoreError) -> ApiError {
        match e {
            crate::store::StoreError::Closed => {
                Degraded::store(self.shared.store_fault().unwrap_or_else(|| e.to_string()))
            }
            e => ApiError::internal(e),
        }
    }
}

/// The document's frame; the paths come from the routes.
#[derive(OpenApi)]
#[openapi(
    info(title = "levelmap mapping server", description = "The map of each fleet: robots, pose network, grid, events."),
    modifiers(&BearerAuth),
    tags(
        (name = "service", description = "Health, metrics, this document, the token"),
        (name = "fleets", description = "Fleets, their summary and robots"),
        (name = "graph", description = "The pose network"),
        (name = "map", description = "The occupancy grid and map products"),
        (name = "nodes", description = "One node of the network"),
        (name = "versions", description = "Map versions: the map frozen, as one file"),
        (name = "localization", description = "Robots localizing on a map version; a scan found on one"),
        (name = "events", description = "The event stream"),
        (name = "web", description = "The dashboard"),
    )
)]
struct ApiDoc;

struct BearerAuth;

impl utoipa::Modify for BearerAuth {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
        );
    }
}

/// Routes anyone may call: the probes, the metrics, the document's frame, the token check
/// and the dashboard's files.
fn open_routes() -> OpenApiRouter<Api> {
    OpenApiRouter::with_openapi(ApiDoc::openapi())
        .routes(routes!(service::healthz))
        .routes(routes!(service::metrics))
        .routes(routes!(access::auth))
        .routes(routes!(web::web_index))
        .routes(routes!(web::web_file))
}

/// Every other route: it needs a token when the mapper has a read token. The router and the
/// document are both made from these two lists.
fn guarded_routes() -> OpenApiRouter<Api> {
    OpenApiRouter::new()
        .routes(routes!(service::openapi))
        .routes(routes!(web::dashboard_settings))
        .routes(routes!(fleets::fleets))
        .routes(routes!(fleets::summary))
        .routes(routes!(fleets::robots))
        .routes(routes!(fleets::robot_pose))
        .routes(routes!(live::live))
        .routes(routes!(fleets::trajectory_tum))
        .routes(routes!(fleets::optimize))
        .routes(routes!(graph::graph))
        .routes(routes!(graph::graph_g2o))
        .routes(routes!(graph::covariances))
        .routes(routes!(map::map_png))
        .routes(routes!(map::map_pgm))
        .routes(routes!(map::map_yaml))
        .routes(routes!(map::map_json))
        .routes(routes!(map::map_geojson))
        .routes(routes!(geo::map_tif))
        .routes(routes!(geo::map_tile))
        .routes(routes!(window::robot_map_png))
        .routes(routes!(nodes::node_detail))
        .routes(routes!(nodes::node_cloud))
        .routes(routes!(versions::version_list, versions::version_freeze))
        .routes(routes!(versions::version_import))
        .routes(routes!(versions::version_summary, versions::version_delete))
        .routes(routes!(versions::version_file))
        .routes(routes!(localize::modes, localize::set_modes))
        .routes(routes!(localize::robot_localizations))
        .routes(routes!(localize::localize))
        .routes(routes!(events::events))
        .routes(routes!(backup::store_backup))
}

/// The router (guarded routes behind the read check when `api` is given) and its document.
fn parts(api: Option<&Api>) -> (Router<Api>, utoipa::openapi::OpenApi) {
    let mut guarded = guarded_routes();
    let paths: Vec<String> = guarded.get_openapi().paths.paths.keys().cloned().collect();
    if let Some(api) = api {
        let check = axum::middleware::from_fn_with_state(api.clone(), access::require_read);
        guarded = guarded.route_layer(check);
    }
    let (router, mut doc) = open_routes().merge(guarded).split_for_parts();
    access::document_guard(&mut doc, &paths);
    // The fleets' 503 (quarantine, a failing store).
    faults::document(&mut doc);
    (router, doc)
}

/// The OpenAPI document of every route, as JSON.
pub fn openapi_json() -> String {
    let (_, doc) = parts(None);
    doc.to_pretty_json().expect("the document serializes")
}

/// The HTTP API over the mapper's views, its worker and its store, with the tokens, limits
/// and CORS of `config`.
pub fn router(
    shared: Arc<Shared>,
    work: mpsc::SyncSender<Work>,
    store: Arc<Store>,
    maps: Arc<crate::localization::MapCache>,
    blobs: Arc<dyn Blobs>,
    config: &MapperConfig,
) -> Router {
    let api = Api {
        shared,
        work,
        marginals: Arc::default(),
        store,
        openapi: Arc::new(OnceLock::new()),
        tokens: Arc::new(access::Tokens::new(&config.token, &config.read_token)),
        limits: Arc::new(limits::Limits::new(&config.http)),
        tiles: Arc::default(),
        served: config.fleets.clone().into(),
        max_versions: config.versions.max_versions.get(),
        blobs,
        maps,
        changes_lock: Arc::default(),
        base_map: config.http.base_map.clone().map(Arc::new),
        backups: Arc::new(backup::Backups::beside(&config.store_path)),
    };
    let (router, doc) = parts(Some(&api));
    let _ = api
        .openapi
        .set(doc.to_pretty_json().expect("the document serializes"));
    let router = router.with_state(api);
    // Outermost, so a preflight (which carries no token) is answered before the token check.
    match access::cors(&config.http.cors_origins) {
        Some(cors) => router.layer(cors),
        None => router,
    }
}

#[cfg(test)]
mod tests;
