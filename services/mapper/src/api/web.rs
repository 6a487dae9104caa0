//! The dashboard: the page and its modules, compiled in (or read from a folder while working
//! on the page).

use super::{Api, ApiError, Reply};
use crate::config::BaseMap;
use axum::Json;
use axum::extract::{Path, State};
use axum::http::header;
use axum::response::IntoResponse;

/// The dashboard (`web/`), compiled in: file name, content type, content.
const WEB_FILES: &[(&str, &str, &str)] = &[
    (
        "index.html",
        "text/html; charset=utf-8",
        include_str!("../../../../web/index.html"),
    ),
    (
        "app.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/app.js"),
    ),
    (
        "follow.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/follow.js"),
    ),
    (
        "cloud.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/cloud.js"),
    ),
    (
        "geo.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/geo.js"),
    ),
    (
        "basemap.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/basemap.js"),
    ),
    (
        "panel.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/panel.js"),
    ),
    (
        "view.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/view.js"),
    ),
    (
        "state.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/state.js"),
    ),
    (
        "data.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/data.js"),
    ),
    (
        "grid.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/grid.js"),
    ),
    (
        "layer.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/layer.js"),
    ),
    (
        "frame.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/frame.js"),
    ),
    (
        "sidebar.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/sidebar.js"),
    ),
    (
        "input.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/input.js"),
    ),
    (
        "auth.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/auth.js"),
    ),
    (
        "stream.js",
        "text/javascript; charset=utf-8",
        include_str!("../../../../web/stream.js"),
    ),
    (
        "style.css",
        "text/css; charset=utf-8",
        include_str!("../../../../web/style.css"),
    ),
];

/// Set to a `web/` folder, the dashboard's files are read from it on every request instead
/// of the compiled-in copies (for working on the page without rebuilding the mapper).
pub const WEB_DIR_ENV: &str = "LEVELMAP_WEB_DIR";

fn web_reply(file: &str) -> Reply {
    if let Some(dir) = std::env::var_os(WEB_DIR_ENV) {
        return web_reply_from_disk(std::path::Path::new(&dir), file);
    }
    let (_, content_type, body) = WEB_FILES
        .iter()
        .find(|(name, _, _)| *name == file)
        .ok_or_else(|| ApiError::NotFound(format!("no file {file:?} in the dashboard")))?;
    Ok((
        [
            (header::CONTENT_TYPE, *content_type),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body.to_string(),
    )
        .into_response())
}

/// A page file read from `dir` (any `.html`, `.js` or `.css` name in it, so a new module
/// works before it is compiled in).
fn web_reply_from_disk(dir: &std::path::Path, file: &str) -> Reply {
    let content_type = [
        (".html", "text/html; charset=utf-8"),
        (".js", "text/javascript; charset=utf-8"),
        (".css", "text/css; charset=utf-8"),
    ]
    .iter()
    .find(|(ext, _)| file.ends_with(ext))
    .map(|(_, t)| *t)
    .filter(|_| !file.contains(['/', '\\']) && !file.starts_with('.'))
    .ok_or_else(|| ApiError::NotFound(format!("no file {file:?} in the dashboard")))?;
    let body = std::fs::read_to_string(dir.join(file))
        .map_err(|e| ApiError::NotFound(format!("{WEB_DIR_ENV}: {file}: {e}")))?;
    Ok((
        [
            (header::CONTENT_TYPE, content_type),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response())
}

/// The dashboard's page.
#[utoipa::path(get, path = "/", tag = "web", responses(
    (status = 200, description = "The dashboard", content_type = "text/html", body = String),
))]
pub(super) async fn web_index() -> Reply {
    web_reply("index.html")
}

/// One of the dashboard's modules or its style sheet.
#[utoipa::path(get, path = "/web/{file}", tag = "web",
    params(("file" = String, Path, description = "A file of the dashboard: app.js, style.css, …")),
    responses(
        (status = 200, description = "The file", content_type = "text/javascript", body = String),
        (status = 404, description = "No such file", body = String),
    ))]
pub(super) async fn web_file(Path(file): Path<String>) -> Reply {
    web_reply(&file)
}

/// What the dashboard draws beyond the mapper's own answers.
#[derive(serde::Serialize, utoipa::ToSchema)]
pub(super) struct DashboardSettings {
    /// The base map under the grid (`[http.base_map]`); null when none is configured.
    base_map: Option<BaseMap>,
}

/// The dashboard's settings from the mapper's config: the base map, if any.
#[utoipa::path(get, path = "/api/v1/dashboard", tag = "web", responses(
    (status = 200, description = "The dashboard's settings", body = DashboardSettings),
))]
pub(super) async fn dashboard_settings(State(api): State<Api>) -> Json<DashboardSettings> {
    Json(DashboardSettings {
        base_map: api.base_map.as_deref().cloned(),
    })
}

#[cfg(test)]
mod tests {
    use super::WEB_FILES;

    /// Every page file in `web/` is compiled in, and nothing else is listed.
    #[test]
    fn web_files_match_the_folder() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../web");
        let mut on_disk: Vec<String> = std::fs::read_dir(dir)
            .expect("web/")
            .map(|e| e.expect("entry").file_name().into_string().expect("utf-8"))
            .filter(|n| [".html", ".js", ".css"].iter().any(|x| n.ends_with(x)))
            .collect();
        on_disk.sort();
        let mut listed: Vec<String> = WEB_FILES.iter().map(|(n, _, _)| n.to_string()).collect();
        listed.sort();
        assert_eq!(on_disk, listed);
    }
}
