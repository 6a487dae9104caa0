//! A backup of the running store, streamed to the caller (`levelmap backup`): a consistent
//! copy ([`crate::store::Store::backup_to`]) written beside the store, unlinked as soon as
//! it is open (nothing is left behind, whatever the client does) and sent as it is read.

use super::access::authorized;
use super::{Api, ApiError, Reply};
use axum::body::{Body, Bytes};
use axum::extract::State;
use axum::http::{HeaderMap, HeaderName, header};
use axum::response::{IntoResponse, Response};
use std::io::Read;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

/// The media type of a backup: a redb file, a store the mapper opens as its own.
const STORE_FILE: &str = "application/vnd.levelmap.store";
/// The answer's header that names each fleet's nodes in the copy (`park=1200,campus=40`).
const BACKUP_FLEETS: HeaderName = HeaderName::from_static("levelmap-backup-fleets");
/// Bytes read and sent at a time; at most [`CHUNKS_AHEAD`] wait in memory.
const CHUNK: usize = 256 * 1024;
const CHUNKS_AHEAD: usize = 4;

/// Where backups are written before they are sent, one at a time.
pub(super) struct Backups {
    /// The store's folder: a copy needs as much room as the store, on the same disk.
    dir: PathBuf,
    running: tokio::sync::Mutex<()>,
    taken: AtomicU64,
}

impl Backups {
    pub(super) fn beside(store_path: &std::path::Path) -> Backups {
        let dir = match store_path.parent() {
            Some(dir) if !dir.as_os_str().is_empty() => dir.to_owned(),
            _ => PathBuf::from("."),
        };
        Backups {
            dir,
            running: tokio::sync::Mutex::new(()),
            taken: AtomicU64::new(0),
        }
    }
}

/// A consistent copy of the mapper's store, taken while it maps (needs the write token):
/// every table as one commit left it. Start a mapper from it with `levelmap mapper
/// --restore FILE`.
#[utoipa::path(post, path = "/api/v1/store/backup", tag = "service",
    security(("bearer" = [])),
    responses(
        (status = 200, description = "The copy (a redb store file), streamed", content_type = "application/vnd.levelmap.store",
            headers(("levelmap-backup-fleets" = String, description = "Each fleet's nodes in the copy: `park=1200,campus=40`"))),
        (status = 401, description = "No valid bearer token", body = String),
        (status = 403, description = "Write routes are off, or the token only reads", body = String),
        (status = 409, description = "A backup is being taken", body = String),
        (status = 503, description = "The store is closed after a failed commit, or the heavy requests' slots are taken", body = String,
            headers(("Retry-After" = u32, description = "Seconds to wait before asking again"))),
    ))]
pub(super) async fn store_backup(State(api): State<Api>, headers: HeaderMap) -> Reply<Response> {
    authorized(&api, &headers)?;
    let Ok(_one_at_a_time) = api.backups.running.try_lock() else {
        return Err(ApiError::Conflict("a backup is being taken".into()));
    };
    let n = api.backups.taken.fetch_add(1, Ordering::Relaxed);
    let path = api
        .backups
        .dir
        .join(format!(".levelmap-backup-{}-{n}.redb", std::process::id()));
    let store = api.store.clone();
    let (report, file) = api
        .limits
        .heavy_write(move || Ok(copy_and_open(&store, &path)))
        .await?
        .map_err(|e| api.store_error(e))?;
    let fleets: Vec<String> = report
        .fleets
        .iter()
        .map(|(fleet, nodes)| format!("{fleet}={nodes}"))
        .collect();
    tracing::info!(bytes = report.bytes, rows = report.rows, fleets = ?fleets, "backup taken");
    let (chunks, stream) = tokio::sync::mpsc::channel::<std::io::Result<Bytes>>(CHUNKS_AHEAD);
    tokio::task::spawn_blocking(move || send_file(file, &chunks));
    let body = Body::from_stream(futures_util::stream::unfold(stream, |mut rx| async move {
        rx.recv().await.map(|chunk| (chunk, rx))
    }));
    let name = format!("attachment; filename=\"levelmap-store-{}.redb\"", n);
    let headers = [
        (header::CONTENT_TYPE, STORE_FILE.to_owned()),
        (header::CONTENT_LENGTH, report.bytes.to_string()),
        (header::CONTENT_DISPOSITION, name),
        (BACKUP_FLEETS, fleets.join(",")),
    ];
    Ok((headers, body).into_response())
}

/// The store's copy at `path`, open and already unlinked: the open file is what is sent.
fn copy_and_open(
    store: &crate::store::Store,
    path: &std::path::Path,
) -> Result<(crate::store::BackupReport, std::fs::File), crate::store::StoreError> {
    let report = store.backup_to(path)?;
    let file = std::fs::File::open(path);
    let _ = std::fs::remove_file(path);
    let file = file.map_err(|e| crate::store::StoreError::backup_file(path, &e))?;
    Ok((report, file))
}

/// Reads `file` into `chunks` until its end, or until the answer is dropped.
fn send_file(mut file: std::fs::File, chunks: &tokio::sync::mpsc::Sender<std::io::Result<Bytes>>) {
    loop {
        let mut buffer = vec![0; CHUNK];
        let chunk = match file.read(&mut buffer) {
            Ok(0) => return,
            Ok(n) => {
                buffer.truncate(n);
                Ok(Bytes::from(buffer))
            }
            Err(e) => Err(e),
        };
        let failed = chunk.is_err();
        if chunks.blocking_send(chunk).is_err() || failed {
            return;
        }
    }
}
