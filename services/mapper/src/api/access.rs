//! Who may call the API: the bearer tokens (read and write), compared in constant time, and
//! the origins whose pages may call it from a browser (CORS).

use super::{Api, ApiError, Reply};
use crate::config::CorsOrigin;
pub(super) use crate::tokens::{Grant, Tokens};
use axum::Json;
use axum::extract::{Request, State};
use axum::http::{HeaderMap, HeaderName, HeaderValue, Method, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use std::time::Duration;
use tower_http::cors::{AllowOrigin, CorsLayer};
use utoipa::ToSchema;
use utoipa::openapi::security::SecurityRequirement;

/// The token of an `Authorization: Bearer …` header (the scheme in any case).
fn bearer(headers: &HeaderMap) -> Option<&[u8]> {
    let value = headers.get(header::AUTHORIZATION)?.as_bytes();
    let space = value.iter().position(|&b| b == b' ')?;
    let (scheme, token) = value.split_at(space);
    scheme
        .eq_ignore_ascii_case(b"bearer")
        .then(|| token.trim_ascii())
        .filter(|t| !t.is_empty())
}

/// Middleware of the guarded routes: 401 without a known token when the mapper has a read
/// token.
pub(super) async fn require_read(State(api): State<Api>, request: Request, next: Next) -> Response {
    if !api.tokens.may_read(bearer(request.headers())) {
        return ApiError::Unauthorized(
            "this mapper needs a bearer token to read (its read_token or token)".into(),
        )
        .into_response();
    }
    next.run(request).await
}

/// Checks that the request carries the write token.
pub(super) fn authorized(api: &Api, headers: &HeaderMap) -> Result<(), ApiError> {
    if !api.tokens.write_routes() {
        return Err(ApiError::Forbidden(
            "write routes are off: no token in the mapper's config".into(),
        ));
    }
    match api.tokens.grant(bearer(headers)) {
        Grant::Write => Ok(()),
        Grant::Read => Err(ApiError::Forbidden(
            "this token only reads: the write token is needed".into(),
        )),
        Grant::None => Err(ApiError::Unauthorized(
            "a valid bearer token is needed".into(),
        )),
    }
}

/// What the mapper takes, and what the request's bearer token may do.
#[derive(Serialize, ToSchema)]
pub(super) struct AuthState {
    /// A write token is configured: the write routes are on.
    write_routes: bool,
    /// The request's token would be taken by the write routes.
    authorized: bool,
    /// Why not, when not.
    reason: Option<String>,
    /// Reading (every other `/api` route) needs a token.
    read_required: bool,
    /// The request may read: no token is needed, or its token is the read or write token.
    read: bool,
}

/// What the request's bearer token may do, asked without meeting a 401: open to anyone, so a
/// page can find out whether it needs a token before it reads (it tells only whether the
/// mapper has tokens and whether the one sent is one of them).
#[utoipa::path(get, path = "/api/v1/auth", tag = "service", security((), ("bearer" = [])), responses(
    (status = 200, description = "The token's standing", body = AuthState),
))]
pub(super) async fn auth(State(api): State<Api>, headers: HeaderMap) -> Reply<Json<AuthState>> {
    let verdict = authorized(&api, &headers);
    Ok(Json(AuthState {
        write_routes: api.tokens.write_routes(),
        authorized: verdict.is_ok(),
        reason: verdict.err().map(|e| e.reason().to_owned()),
        read_required: api.tokens.read_required(),
        read: api.tokens.may_read(bearer(&headers)),
    }))
}

/// Marks the guarded operations in the document: a bearer token is optional (needed when the
/// mapper has a read token) and a 401 may come. Operations with their own `security` keep it.
pub(super) fn document_guard(doc: &mut utoipa::openapi::OpenApi, guarded: &[String]) {
    use utoipa::openapi::{RefOr, ResponseBuilder};
    for (path, item) in doc.paths.paths.iter_mut() {
        if !guarded.contains(path) {
            continue;
        }
        for op in [&mut item.get, &mut item.post, &mut item.delete]
            .into_iter()
            .flatten()
        {
            op.security.get_or_insert_with(|| {
                vec![
                    SecurityRequirement::default(),
                    SecurityRequirement::new("bearer", Vec::<String>::new()),
                ]
            });
            op.responses
                .responses
                .entry("401".into())
                .or_insert_with(|| {
                    RefOr::T(
                        ResponseBuilder::new()
                            .description(
                                "No known bearer token, and the mapper has a read token \
                                 (WWW-Authenticate: Bearer)",
                            )
                            .build(),
                    )
                });
        }
    }
}

/// The CORS layer of the allow-list; none for an empty list (no CORS headers at all).
pub(super) fn cors(origins: &[CorsOrigin]) -> Option<CorsLayer> {
    if origins.is_empty() {
        return None;
    }
    let origins = origins.iter().map(|o| {
        // Checked when the config was read: scheme, host and port, in plain ASCII.
        HeaderValue::from_str(o.as_str()).expect("a checked origin is a header value")
    });
    Some(
        CorsLayer::new()
            .allow_origin(AllowOrigin::list(origins))
            // DELETE and a Content-Type: a map version's delete and import.
            .allow_methods([Method::GET, Method::POST, Method::PUT, Method::DELETE])
            .allow_headers([header::AUTHORIZATION, header::CONTENT_TYPE])
            // What a page of another origin may read besides the simple headers.
            .expose_headers([
                HeaderName::from_static("levelmap-grid"),
                header::RETRY_AFTER,
                header::WWW_AUTHENTICATE,
                header::LOCATION,
                header::CONTENT_DISPOSITION,
            ])
            .max_age(Duration::from_secs(600)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with(value: &str) -> HeaderMap {
        let mut h = HeaderMap::new();
        h.insert(header::AUTHORIZATION, HeaderValue::from_str(value).unwrap());
        h
    }

    #[test]
    fn tokens_grant_what_they_are() {
        let t = Tokens::new("w-secret", "r-secret");
        assert_eq!(t.grant(bearer(&with("Bearer w-secret"))), Grant::Write);
        assert_eq!(t.grant(bearer(&with("bearer r-secret"))), Grant::Read);
        // A prefix, an extension, another scheme, no token: nothing.
        for v in [
            "Bearer w-secre",
            "Bearer w-secretX",
            "Basic w-secret",
            "Bearer ",
            "w-secret",
        ] {
            assert_eq!(t.grant(bearer(&with(v))), Grant::None, "{v}");
        }
        assert_eq!(t.grant(bearer(&HeaderMap::new())), Grant::None);
        assert!(!t.may_read(bearer(&HeaderMap::new())));
        assert!(t.may_read(bearer(&with("Bearer r-secret"))));
    }

    #[test]
    fn without_a_read_token_anyone_reads_and_nothing_is_a_token() {
        let t = Tokens::new("", "");
        assert!(t.may_read(bearer(&HeaderMap::new())) && !t.read_required() && !t.write_routes());
        // An empty configured token is never matched, even by an empty bearer.
        assert_eq!(t.grant(bearer(&with("Bearer  "))), Grant::None);
    }
}
