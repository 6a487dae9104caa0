//! Localization on map versions: robots' modes (map, or localize on a version), their
//! localizations, and `POST …/localize`, a scan found on a version for teleoperation
//! backends and lost robots.

use super::access::authorized;
use super::{Api, ApiError, Reply};
use crate::localization::{FleetModes, NodeLocalization, RobotMode};
use crate::store::{ModeError, SiteChange};
use axum::Json;
use axum::body::Body;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use slam::Pose2;
use slam::localize::{LocalizeError, SearchKind, TrackStatus};
use std::collections::{BTreeMap, HashMap};
use std::time::Instant;
use utoipa::{IntoParams, ToSchema};
use wire::Message;

const PROTOBUF: &str = "application/x-protobuf";
/// A localize request is one leveled scan: far less than this.
const MAX_REQUEST_BYTES: usize = 1 << 20;

/// A fleet's modes and each localizing robot's newest localization.
#[derive(Serialize, ToSchema)]
pub(super) struct ModesView {
    fleet: String,
    /// The fleet's mode, and robots' own.
    modes: FleetModes,
    /// Each robot that localized: its newest localization.
    localizations: BTreeMap<String, NodeLocalization>,
}

/// A change of mode: every robot (no `robots`: the fleet's mode, robots' own removed) or
/// the robots named.
#[derive(Deserialize, ToSchema)]
pub(super) struct SetModes {
    /// `{"mode": "map"}` or `{"mode": "localize", "version": N}`.
    #[serde(flatten)]
    mode: RobotMode,
    /// The robots to set; none: every robot.
    robots: Option<Vec<String>>,
}

/// A fleet's robots' modes.
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/modes", tag = "localization",
    params(("fleet" = String, Path, description = "Fleet id")),
    responses(
        (status = 200, description = "The modes and the newest localizations", body = ModesView),
        (status = 404, description = "A fleet this mapper does not serve", body = String),
    ))]
pub(super) async fn modes(
    State(api): State<Api>,
    Path(fleet): Path<String>,
) -> Reply<Json<ModesView>> {
    api.versions_of(&fleet)?;
    Ok(Json(api.modes_view(&fleet)?))
}

/// Sets robots to `localize` on a map version, or back to `map` (needs the bearer token).
/// The version's map is built first (seconds for a large map); the worker uses the new
/// modes from its next node on. Kept in the store: a restart keeps them.
#[utoipa::path(put, path = "/api/v1/fleets/{fleet}/modes", tag = "localization",
    params(("fleet" = String, Path, description = "Fleet id")),
    request_body = SetModes,
    security(("bearer" = [])),
    responses(
        (status = 200, description = "The modes now", body = ModesView),
        (status = 400, description = "A robot id that is not valid", body = String),
        (status = 401, description = "No valid bearer token", body = String),
        (status = 403, description = "Write routes are off, or the token only reads", body = String),
        (status = 404, description = "No such fleet or version", body = String),
        (status = 422, description = "The version's map cannot be localized on", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes; in cluster mode, this host does not hold the site now (a gateway finds its owner)", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn set_modes(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    headers: HeaderMap,
    body: axum::body::Bytes,
) -> Reply<Json<ModesView>> {
    // The token first: a caller without one learns nothing of the body's faults.
    authorized(&api, &headers)?;
    api.versions_of(&fleet)?;
    let change: SetModes = serde_json::from_slice(&body)
        .map_err(|e| ApiError::BadRequest(format!("not a change of mode: {e}")))?;
    for robot in change.robots.iter().flatten() {
        wire::validate_id("robot", robot).map_err(|e| ApiError::BadRequest(e.to_string()))?;
    }
    let _one_at_a_time = api.changes_lock.lock().await;
    let version = change.mode.stored();
    api.limits
        .heavy_write({
            let (api, fleet) = (api.clone(), fleet.clone());
            move || {
                if version != 0 {
                    // Built before it is journaled: a map that cannot be used is never set.
                    api.maps
                        .get(&api.store, &fleet, version)
                        .map_err(|e| map_error(&api, e))?;
                }
                api.store
                    .mode_version_exists(&fleet, version)
                    .map_err(|e| mode_error(&api, e))
            }
        })
        .await?;
    let set = SiteChange::ModesSet {
        robots: change.robots,
        version,
    };
    api.change_site(&fleet, set, None).await?;
    let (modes, maps) = api
        .limits
        .heavy_write({
            let (api, fleet) = (api.clone(), fleet.clone());
            move || {
                let modes = api.stored_modes(&fleet)?;
                let mut maps = HashMap::new();
                for v in modes.versions() {
                    maps.insert(
                        v,
                        api.maps
                            .get(&api.store, &fleet, v)
                            .map_err(|e| map_error(&api, e))?,
                    );
                }
                Ok((modes, maps))
            }
        })
        .await?;
    let (reply, done) = tokio::sync::oneshot::channel();
    let work = crate::inbox::Work::SetModes {
        fleet: fleet.clone(),
        modes,
        maps,
        reply,
    };
    api.work
        .send(work)
        .map_err(|_| ApiError::Unavailable("the mapping worker stopped".into()))?;
    done.await
        .map_err(|_| ApiError::Unavailable("the mapping worker stopped".into()))?;
    Ok(Json(api.modes_view(&fleet)?))
}

/// Which localizations to list.
#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub(super) struct Since {
    /// Only nodes from this node_seq on.
    #[serde(default)]
    since: u64,
}

/// A localizing robot's recent localizations (`[localization] history` of them), oldest
/// first.
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/robots/{robot}/localization", tag = "localization",
    params(("fleet" = String, Path, description = "Fleet id"),
        ("robot" = String, Path, description = "Robot id"), Since),
    responses(
        (status = 200, description = "Its localizations", body = Vec<NodeLocalization>),
        (status = 404, description = "No such fleet, or the robot never localized here", body = String),
    ))]
pub(super) async fn robot_localizations(
    State(api): State<Api>,
    Path((fleet, robot)): Path<(String, String)>,
    Query(since): Query<Since>,
) -> Reply<Json<Vec<NodeLocalization>>> {
    api.versions_of(&fleet)?;
    api.shared
        .localizations
        .of(&fleet, &robot, since.since)
        .map(Json)
        .ok_or_else(|| ApiError::NotFound(format!("robot {robot:?} never localized in {fleet:?}")))
}

/// A scan to find, as JSON.
#[derive(Deserialize, ToSchema)]
pub(super) struct LocalizeBody {
    /// Bearing of each beam (rad, counter-clockwise from x forward).
    bearings_rad: Vec<f32>,
    /// Range of each beam (m; 0: no return).
    ranges_m: Vec<f32>,
    /// A guess of the scan frame's pose; none: a global search.
    prior: Option<PriorBody>,
    /// The map version; none: the fleet's newest.
    version: Option<u64>,
}

/// A guess and how far off it may be.
#[derive(Deserialize, ToSchema)]
pub(super) struct PriorBody {
    /// The guess (map frame).
    pose: Pose2,
    /// 1σ in x and in y (m); default 0.5. The window searched is 3σ.
    sigma_xy_m: Option<f64>,
    /// 1σ in yaw (rad); default 0.1.
    sigma_yaw_rad: Option<f64>,
}

/// Where the scan is, or why it was not found.
#[derive(Serialize, ToSchema)]
pub(super) struct LocalizeAnswer {
    /// The version searched.
    version: u64,
    /// Whether it was found.
    found: bool,
    /// The scan frame's pose in the map frame.
    pose: Option<Pose2>,
    /// Covariance of (x, y, yaw) (m², m·rad, rad²).
    covariance: Option<[[f64; 3]; 3]>,
    /// The correlative score (0–1).
    score: Option<f64>,
    /// The refining match's quality (0–1).
    quality: Option<f64>,
    /// "window" (around the prior) or "global" (the whole map: no prior, or none found in
    /// its window).
    #[schema(value_type = Option<String>)]
    search: Option<SearchKind>,
    /// Candidates the search scored.
    candidates: Option<usize>,
    /// Why not found.
    reason: Option<String>,
    /// Time the search took (ms).
    took_ms: f64,
}

/// Finds a leveled scan on a map version: in a window of 3σ around the prior, then (when
/// nothing is found there, or with no prior) over the whole map and every heading. The
/// body is JSON (`LocalizeBody`) or protobuf (`levelmap.v1.LocalizeRequest`, answered with
/// `levelmap.v1.Localization`). A scan not found is answered 200 with `found: false`.
#[utoipa::path(post, path = "/api/v1/fleets/{fleet}/localize", tag = "localization",
    params(("fleet" = String, Path, description = "Fleet id")),
    request_body(content = LocalizeBody, description = "JSON, or a levelmap.v1.LocalizeRequest as application/x-protobuf"),
    responses(
        (status = 200, description = "Where the scan is, or why not", body = LocalizeAnswer),
        (status = 400, description = "Not a valid scan or prior", body = String),
        (status = 404, description = "No such fleet, or no version to localize on", body = String),
        (status = 413, description = "A body over 1 MiB", body = String),
        (status = 422, description = "The version's map cannot be localized on", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn localize(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    headers: HeaderMap,
    body: Body,
) -> Reply<Response> {
    api.versions_of(&fleet)?;
    let bytes = axum::body::to_bytes(body, MAX_REQUEST_BYTES)
        .await
        .map_err(|e| {
            ApiError::TooLarge(format!(
                "not read whole within {MAX_REQUEST_BYTES} bytes: {e}"
            ))
        })?;
    let protobuf = headers
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(PROTOBUF.as_bytes()));
    // Either form is checked once, by wire: the same checks.
    let query = if protobuf {
        wire::decode_localize_request(&bytes)
    } else {
        let body: LocalizeBody = serde_json::from_slice(&bytes)
            .map_err(|e| ApiError::BadRequest(format!("not a localize request: {e}")))?;
        let prior = body.prior.map(|p| (p.pose, p.sigma_xy_m, p.sigma_yaw_rad));
        let version = body.version.unwrap_or(0);
        wire::localize_query(&body.bearings_rad, &body.ranges_m, prior, version)
    }
    .map_err(|e| ApiError::BadRequest(e.to_string()))?;
    let scan = query.scan2(api.maps.max_range_m());
    let (prior, version) = (query.prior_window(), query.map_version);
    let fleet_id = fleet.clone();
    let answer = api
        .limits
        .heavy({
            let api = api.clone();
            move || {
                let version = match version {
                    0 => api.newest_version(&fleet)?,
                    v => v,
                };
                let map = api
                    .maps
                    .get(&api.store, &fleet, version)
                    .map_err(|e| map_error(&api, e))?;
                let started = Instant::now();
                let result = map.relocalize(&scan, prior.as_ref());
                Ok(answer(
                    version,
                    result,
                    started.elapsed().as_secs_f64() * 1e3,
                ))
            }
        })
        .await?;
    if protobuf {
        let message = wire::Localized {
            fleet: fleet_id,
            robot: String::new(),
            chain_id: 0,
            node_seq: 0,
            map_version: answer.version,
            status: match answer.found {
                true => TrackStatus::Localized,
                false => TrackStatus::Lost,
            },
            pose: answer.pose,
            covariance: answer.covariance,
            score: answer.score.unwrap_or(0.0),
            search: answer.search,
            sent_ns: runtime::session::now_ns(),
            reason: answer.reason.clone().unwrap_or_default(),
        };
        let message = wire::localization_to_wire(&message);
        return Ok(([(header::CONTENT_TYPE, PROTOBUF)], message.encode_to_vec()).into_response());
    }
    Ok(Json(answer).into_response())
}

fn answer(
    version: u64,
    result: Result<slam::localize::Localization, LocalizeError>,
    took_ms: f64,
) -> LocalizeAnswer {
    match result {
        Ok(l) => LocalizeAnswer {
            version,
            found: true,
            pose: Some(l.pose),
            covariance: Some(l.covariance),
            score: Some(l.score),
            quality: Some(l.quality),
            search: Some(l.search),
            candidates: Some(l.candidates),
            reason: None,
            took_ms,
        },
        Err(e) => LocalizeAnswer {
            version,
            found: false,
            pose: None,
            covariance: None,
            score: None,
            quality: None,
            search: None,
            candidates: None,
            reason: Some(e.to_string()),
            took_ms,
        },
    }
}

fn map_error(api: &Api, e: crate::localization::MapError) -> ApiError {
    use crate::localization::MapError;
    match e {
        MapError::NoVersion { .. } => ApiError::NotFound(e.to_string()),
        MapError::File { .. } | MapError::Map { .. } => ApiError::Unprocessable(e.to_string()),
        MapError::Store(e) => api.store_error(e),
    }
}

fn mode_error(api: &Api, e: ModeError) -> ApiError {
    match e {
        ModeError::NoVersion { .. } => ApiError::NotFound(e.to_string()),
        ModeError::InUse { .. } => ApiError::Conflict(e.to_string()),
        ModeError::Store(e) => api.store_error(e),
    }
}

impl Api {
    fn stored_modes(&self, fleet: &str) -> Reply<FleetModes> {
        let all = self.store.modes().map_err(|e| self.store_error(e))?;
        Ok(all
            .iter()
            .find(|(f, _)| f == fleet)
            .map(|(_, m)| crate::localization::modes_of(m))
            .unwrap_or_default())
    }

    fn modes_view(&self, fleet: &str) -> Reply<ModesView> {
        Ok(ModesView {
            fleet: fleet.to_owned(),
            modes: self.stored_modes(fleet)?,
            localizations: self.shared.localizations.newest(fleet),
        })
    }

    fn newest_version(&self, fleet: &str) -> Reply<u64> {
        let versions = self
            .store
            .version_summaries(fleet)
            .map_err(|e| self.store_error(e))?;
        versions.last().map(|(v, _)| *v).ok_or_else(|| {
            ApiError::NotFound(format!("fleet {fleet:?} has no map version to localize on"))
        })
    }
}
