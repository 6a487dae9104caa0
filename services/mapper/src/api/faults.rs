//! The 503 answers of a degraded mapper, as JSON with the reason: a quarantined fleet (its
//! stored map did not replay at start) and a store that cannot commit (a full disk).

use super::ApiError;
use serde::Serialize;
use utoipa::openapi::{ContentBuilder, OpenApi, Ref, RefOr, ResponseBuilder};
use utoipa::{PartialSchema, ToSchema};

/// What a client is asked to wait (s) while the store cannot commit; the worker tries again
/// every second.
pub const RETRY_AFTER_S: u64 = 5;

/// The body of a 503: what cannot serve now, and why.
#[derive(Debug, Serialize, ToSchema)]
pub struct Degraded {
    /// `quarantined`: the fleet's stored map did not replay at start, and an operator must
    /// repair or remove its rows; `store`: the store cannot commit (a full disk), which
    /// passes by itself when the disk has room again.
    pub fault: String,
    /// The fleet, for `quarantined`.
    pub fleet: Option<String>,
    /// What failed.
    pub reason: String,
    /// When to ask again (s), for a fault that passes by itself (also as `Retry-After`).
    pub retry_after_s: Option<u64>,
}

impl Degraded {
    /// A quarantined fleet's answer.
    pub fn quarantined(fleet: &str, reason: String) -> ApiError {
        ApiError::Degraded(Degraded {
            fault: "quarantined".into(),
            fleet: Some(fleet.to_owned()),
            reason,
            retry_after_s: None,
        })
    }

    /// The answer of a route that needs the store while it cannot commit.
    pub fn store(reason: String) -> ApiError {
        ApiError::Degraded(Degraded {
            fault: "store".into(),
            fleet: None,
            reason,
            retry_after_s: Some(RETRY_AFTER_S),
        })
    }
}

/// Documents the 503 of every route of a fleet (each answers it for a quarantined fleet, and
/// those that need the store while it cannot commit), with [`Degraded`] as its body.
pub fn document(doc: &mut OpenApi) {
    let components = doc.components.get_or_insert_with(Default::default);
    components
        .schemas
        .insert("Degraded".into(), Degraded::schema());
    for (path, item) in doc.paths.paths.iter_mut() {
        if !path.contains("{fleet}") {
            continue;
        }
        for op in [&mut item.get, &mut item.post, &mut item.delete]
            .into_iter()
            .flatten()
        {
            let faults = "the fleet is quarantined (its stored map did not replay), or the \
                          store cannot commit (`Retry-After`)";
            let json = ContentBuilder::new()
                .schema(Some(Ref::from_schema_name("Degraded")))
                .build();
            // A route with a 503 of its own (a stopping mapper, as text) keeps it.
            let response = match op.responses.responses.remove("503") {
                Some(RefOr::T(mut own)) => {
                    own.description = format!("{}; or {faults}", own.description);
                    own.content
                        .insert("application/json".into(), RefOr::T(json));
                    own
                }
                _ => ResponseBuilder::new()
                    .description(format!("{}{}", faults[..1].to_uppercase(), &faults[1..]))
                    .content("application/json", json)
                    .build(),
            };
            op.responses
                .responses
                .insert("503".into(), RefOr::T(response));
        }
    }
}
