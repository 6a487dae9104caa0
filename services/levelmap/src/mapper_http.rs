//! The commands that talk to a running mapper's HTTP API (`map export|import`, `backup`):
//! where it is, the token, the client, and a refusal as an error.

use clap::Args;
use std::time::Duration;

/// The mapper's HTTP API by default (deploy/mapper.toml's http_listen).
const DEFAULT_MAPPER: &str = "http://127.0.0.1:8080";

/// Where the mapper is, and the token it wants.
#[derive(Args, Debug)]
pub(crate) struct MapperArgs {
    /// The mapper's HTTP API (plain HTTP).
    #[arg(long, value_name = "URL", default_value = DEFAULT_MAPPER)]
    pub(crate) mapper: String,
    /// Bearer token: the read (or write) token to export, the write token to import or to
    /// take a backup.
    #[arg(long, value_name = "TOKEN")]
    pub(crate) token: Option<String>,
}

impl MapperArgs {
    pub(crate) fn url(&self, path: &str) -> String {
        let base = self.mapper.trim_end_matches('/');
        match base.contains("://") {
            true => format!("{base}{path}"),
            false => format!("http://{base}{path}"),
        }
    }
}

pub(crate) fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .timeout_connect(Some(Duration::from_secs(10)))
        .build()
        .into()
}

pub(crate) fn refused(url: &str, status: u16, body: &[u8]) -> anyhow::Error {
    let why = String::from_utf8_lossy(body);
    anyhow::anyhow!("{url}: the mapper answered {status}: {}", why.trim())
}
