//! Map versions: freeze a fleet's map, list, read, export and delete versions, import one
//! from another mapper's file ([`crate::versions`]). Making, importing and deleting need the
//! write token; each is made on the blocking pool, journaled by the worker
//! ([`Api::change_site`]) and waited for to its end.

use super::access::authorized;
use super::{Api, ApiError, Reply};
use crate::store::{AddVersionError, ModeError, SiteChange};
use crate::versions::{VersionError, VersionSummary};
use axum::Json;
use axum::body::Body;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use runtime::session::now_ns;
use serde::Serialize;
use utoipa::ToSchema;
use wire::MAX_MAP_VERSION_BYTES;

/// The media type of a version file.
const PROTOBUF: &str = "application/x-protobuf";

/// A fleet's versions.
#[derive(Serialize, ToSchema)]
pub(super) struct VersionList {
    fleet: String,
    /// Versions the fleet keeps at most (`[versions] max_versions`).
    max_versions: usize,
    /// Its versions, oldest first.
    versions: Vec<VersionSummary>,
}

impl Api {
    /// 503 for a quarantined fleet, 404 for one this mapper does not serve.
    pub(super) fn versions_of(&self, fleet: &str) -> Reply<()> {
        self.available(fleet)?;
        if self.served.iter().any(|f| f == fleet) {
            Ok(())
        } else {
            Err(ApiError::NotFound(format!(
                "fleet {fleet:?} is not served by this mapper (its config's fleets)"
            )))
        }
    }

    fn no_version(fleet: &str, version: u64) -> ApiError {
        ApiError::NotFound(format!(
            "no version {version} in fleet {fleet:?} (deleted, or never made)"
        ))
    }

    /// Why a version was not stored, as an answer.
    fn add_error(&self, e: AddVersionError<VersionError>) -> ApiError {
        match e {
            AddVersionError::Full { .. } => ApiError::Conflict(e.to_string()),
            AddVersionError::Make(e) => ApiError::Unprocessable(e.to_string()),
            AddVersionError::Store(e) => self.store_error(e),
        }
    }
}

/// 201 with the new version's summary and where it is.
fn created(summary: VersionSummary) -> Response {
    let location = format!(
        "/api/v1/fleets/{}/versions/{}",
        summary.fleet, summary.version
    );
    (
        StatusCode::CREATED,
        [(header::LOCATION, location)],
        Json(summary),
    )
        .into_response()
}

/// Freezes the fleet's map now as its next version (needs the bearer token): every node's
/// pose and leveled scan, the GPS datum and the occupancy grid, kept unchanged until deleted.
#[utoipa::path(post, path = "/api/v1/fleets/{fleet}/versions", tag = "versions",
    params(("fleet" = String, Path, description = "Fleet id")),
    security(("bearer" = [])),
    responses(
        (status = 201, description = "The new version (its URL in Location)", body = VersionSummary),
        (status = 401, description = "No valid bearer token", body = String),
        (status = 403, description = "Write routes are off, or the token only reads", body = String),
        (status = 404, description = "No such fleet, or no node in it yet", body = String),
        (status = 409, description = "The fleet keeps max_versions versions already: delete one", body = String),
        (status = 422, description = "The map is too large for one version file", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes; in cluster mode, this host does not hold the site now (a gateway finds its owner)", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn version_freeze(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    headers: HeaderMap,
) -> Reply {
    authorized(&api, &headers)?;
    api.versions_of(&fleet)?;
    let view = api.view(&fleet)?;
    store_new(&api, fleet, move || {
        crate::versions::freeze(&view, now_ns()).map_err(|e| ApiError::Unprocessable(e.to_string()))
    })
    .await
}

/// Takes a version file (`levelmap map export`, or `GET …/versions/{version}/file` of another
/// mapper) into this fleet as its next version (needs the bearer token). The file is checked
/// whole first: a damaged or cut file, or one of another format version, is refused and
/// nothing is stored.
#[utoipa::path(post, path = "/api/v1/fleets/{fleet}/versions/import", tag = "versions",
    params(("fleet" = String, Path, description = "Fleet id: the version is taken into this fleet")),
    request_body(content = Vec<u8>, content_type = "application/x-protobuf",
        description = "A version file (levelmap.v1.MapVersionFile)"),
    security(("bearer" = [])),
    responses(
        (status = 201, description = "The version as stored here: its number in this fleet, where it came from", body = VersionSummary),
        (status = 400, description = "Not a version file this mapper reads: damaged, cut short, another format version; nothing stored", body = String),
        (status = 401, description = "No valid bearer token", body = String),
        (status = 403, description = "Write routes are off, or the token only reads", body = String),
        (status = 404, description = "A fleet this mapper does not serve", body = String),
        (status = 409, description = "The fleet keeps max_versions versions already: delete one", body = String),
        (status = 413, description = "A file over 256 MiB", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes; in cluster mode, this host does not hold the site now (a gateway finds its owner)", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn version_import(
    State(api): State<Api>,
    Path(fleet): Path<String>,
    headers: HeaderMap,
    body: Body,
) -> Reply {
    authorized(&api, &headers)?;
    api.versions_of(&fleet)?;
    let file = axum::body::to_bytes(body, MAX_MAP_VERSION_BYTES)
        .await
        .map_err(|e| {
            ApiError::TooLarge(format!(
                "the file was not read whole within {MAX_MAP_VERSION_BYTES} bytes: {e}"
            ))
        })?;
    store_new(&api, fleet.clone(), move || {
        crate::versions::import(&fleet, &file, now_ns()).map_err(|e| {
            ApiError::BadRequest(format!("not a map version file: {e}; nothing stored"))
        })
    })
    .await
}

/// A version made by `make` and journaled as the fleet's next (numbered by the store,
/// which holds every change of the site the worker journaled; its file shared first where
/// other hosts read it): 201 with its summary.
async fn store_new(
    api: &Api,
    fleet: String,
    make: impl FnOnce() -> Reply<wire::MapVersion> + Send + 'static,
) -> Reply {
    let _one_at_a_time = api.changes_lock.lock().await;
    let (summary, rows) = api
        .limits
        .heavy_write({
            let (api, fleet) = (api.clone(), fleet.clone());
            move || {
                let version = make()?;
                let number = api
                    .store
                    .next_version_number(&fleet, api.max_versions)
                    .map_err(|e| api.add_error(e))?;
                crate::versions::numbered(version, number)
                    .map_err(|e| api.add_error(AddVersionError::Make(e)))
            }
        })
        .await?;
    let host = api
        .blobs
        .put_version_file(&fleet, summary.version, &rows.file)
        .await
        .map_err(ApiError::Unavailable)?;
    let added = SiteChange::VersionAdded {
        number: summary.version,
        summary: rows.summary,
        host,
    };
    api.change_site(&fleet, added, Some(rows.file)).await?;
    Ok(created(summary))
}

/// The fleet's versions, oldest first.
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/versions", tag = "versions",
    params(("fleet" = String, Path, description = "Fleet id")),
    responses(
        (status = 200, description = "Each version's summary", body = VersionList),
        (status = 404, description = "A fleet this mapper does not serve", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn version_list(
    State(api): State<Api>,
    Path(fleet): Path<String>,
) -> Reply<Json<VersionList>> {
    api.versions_of(&fleet)?;
    let versions = api
        .limits
        .heavy({
            let (api, fleet) = (api.clone(), fleet.clone());
            move || {
                let rows = api
                    .store
                    .version_summaries(&fleet)
                    .map_err(|e| api.store_error(e))?;
                rows.iter()
                    .map(|(_, json)| serde_json::from_slice(json).map_err(ApiError::internal))
                    .collect()
            }
        })
        .await?;
    Ok(Json(VersionList {
        fleet,
        max_versions: api.max_versions,
        versions,
    }))
}

/// One version's summary.
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/versions/{version}", tag = "versions",
    params(("fleet" = String, Path, description = "Fleet id"), ("version" = u64, Path, description = "Version number")),
    responses(
        (status = 200, description = "The version's summary", body = VersionSummary),
        (status = 404, description = "No such fleet or version", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn version_summary(
    State(api): State<Api>,
    Path((fleet, version)): Path<(String, u64)>,
) -> Reply<Json<VersionSummary>> {
    api.versions_of(&fleet)?;
    let summary = api
        .limits
        .heavy({
            let api = api.clone();
            move || {
                let json = api
                    .store
                    .version_summary(&fleet, version)
                    .map_err(|e| api.store_error(e))?
                    .ok_or_else(|| Api::no_version(&fleet, version))?;
                serde_json::from_slice(&json).map_err(ApiError::internal)
            }
        })
        .await?;
    Ok(Json(summary))
}

/// The version as one file (levelmap.v1.MapVersionFile, protobuf): what `levelmap map export`
/// saves and `POST …/versions/import` takes.
#[utoipa::path(get, path = "/api/v1/fleets/{fleet}/versions/{version}/file", tag = "versions",
    params(("fleet" = String, Path, description = "Fleet id"), ("version" = u64, Path, description = "Version number")),
    responses(
        (status = 200, description = "The version file", content_type = "application/x-protobuf", body = Vec<u8>),
        (status = 404, description = "No such fleet or version", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes, or not done in time", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn version_file(
    State(api): State<Api>,
    Path((fleet, version)): Path<(String, u64)>,
) -> Reply {
    api.versions_of(&fleet)?;
    let name = format!("attachment; filename=\"{fleet}-v{version}.mapversion\"");
    let file = api
        .limits
        .heavy({
            let api = api.clone();
            move || {
                api.store
                    .version_file(&fleet, version)
                    .map_err(|e| api.store_error(e))?
                    .ok_or_else(|| Api::no_version(&fleet, version))
            }
        })
        .await?;
    let headers = [
        (header::CONTENT_TYPE, PROTOBUF.to_owned()),
        (header::CONTENT_DISPOSITION, name),
    ];
    Ok((headers, file).into_response())
}

/// Deletes a version (needs the bearer token); its number is not given again.
#[utoipa::path(delete, path = "/api/v1/fleets/{fleet}/versions/{version}", tag = "versions",
    params(("fleet" = String, Path, description = "Fleet id"), ("version" = u64, Path, description = "Version number")),
    security(("bearer" = [])),
    responses(
        (status = 204, description = "Deleted"),
        (status = 401, description = "No valid bearer token", body = String),
        (status = 403, description = "Write routes are off, or the token only reads", body = String),
        (status = 404, description = "No such fleet or version", body = String),
        (status = 409, description = "Robots localize on the version (set them to map or to another version first)", body = String),
        (status = 503, description = "Busy: as many heavy requests as the mapper takes; in cluster mode, this host does not hold the site now (a gateway finds its owner)", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn version_delete(
    State(api): State<Api>,
    Path((fleet, version)): Path<(String, u64)>,
    headers: HeaderMap,
) -> Reply<StatusCode> {
    authorized(&api, &headers)?;
    api.versions_of(&fleet)?;
    let _one_at_a_time = api.changes_lock.lock().await;
    api.limits
        .heavy_write({
            let (api, fleet) = (api.clone(), fleet.clone());
            move || match api.store.deletable(&fleet, version) {
                Ok(true) => Ok(()),
                Ok(false) => Err(Api::no_version(&fleet, version)),
                Err(e @ ModeError::InUse { .. }) => Err(ApiError::Conflict(e.to_string())),
                Err(ModeError::Store(e)) => Err(api.store_error(e)),
                Err(e @ ModeError::NoVersion { .. }) => Err(ApiError::NotFound(e.to_string())),
            }
        })
        .await?;
    let deleted = SiteChange::VersionDeleted { number: version };
    api.change_site(&fleet, deleted, None).await?;
    // The record is the truth: a file left behind is only space (a host reading the log
    // skips a deleted version's file either way).
    if let Err(e) = api.blobs.delete_version_file(&fleet, version).await {
        tracing::warn!(fleet, version, "the deleted version's file stays: {e}");
    }
    Ok(StatusCode::NO_CONTENT)
}
