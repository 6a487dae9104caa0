//! The Zenoh session of a levelmap service: mode and endpoints from the service's config file;
//! the config loader both services share ([`load_toml`], with [`mod@env`] overrides).

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::{SystemTime, UNIX_EPOCH};

/// Wall-clock time in ns since the Unix epoch, as the wire's stamps are.
pub fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

pub mod env;

/// Reads a service's config: its TOML file (none: every key at its default), then the
/// `LEVELMAP_…` variables of the environment ([`mod@env`]). Unknown keys are errors, in the file
/// when `T` denies them, in the environment always (a typo must not silently become a
/// default). Errors name the file or the variable.
pub fn load_toml<T>(path: Option<&Path>) -> anyhow::Result<T>
where
    T: DeserializeOwned + Serialize + Default,
{
    load_toml_with(path, std::env::vars_os())
}

/// [`load_toml`] with the environment given: `vars` as `std::env::vars_os` yields them.
pub fn load_toml_with<T>(
    path: Option<&Path>,
    vars: impl IntoIterator<Item = (std::ffi::OsString, std::ffi::OsString)>,
) -> anyhow::Result<T>
where
    T: DeserializeOwned + Serialize + Default,
{
    let overrides = env::env_overrides(vars)?;
    let mut table = match path {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            // The file alone first: its errors keep their line and column.
            let alone: T =
                toml::from_str(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            if overrides.is_empty() {
                return Ok(alone);
            }
            toml::from_str::<toml::Table>(&text)?
        }
        None => toml::Table::new(),
    };
    let defaults = toml::Table::try_from(T::default())?;
    env::apply_overrides(&mut table, &defaults, &overrides)?;
    let vars: Vec<&str> = overrides.iter().map(|o| o.var.as_str()).collect();
    let origin = match path {
        Some(path) => format!("{} with {}", path.display(), vars.join(", ")),
        None => vars.join(", "),
    };
    let config: T = toml::Value::Table(table)
        .try_into()
        .map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
    env::check_taken(&toml::Table::try_from(&config)?, &overrides)?;
    Ok(config)
}

/// The largest Zenoh message a levelmap session takes: twice the largest valid node
/// ([`crate::MAX_NODE_BYTES`]), so every valid node fits with room for its framing.
pub const MAX_MESSAGE_BYTES: usize = 2 * crate::MAX_NODE_BYTES;

/// Where a service's Zenoh session listens and connects. Mirrors Zenoh's own config keys
/// (`mode`, `listen/endpoints`, `connect/endpoints`, `scouting/multicast/enabled`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SessionConfig {
    /// `router`, `peer` or `client`.
    pub mode: String,
    /// Endpoints to listen on, e.g. `tcp/0.0.0.0:7447`.
    pub listen: Vec<String>,
    /// Endpoints to connect to, e.g. `tcp/mapper.local:7447`.
    pub connect: Vec<String>,
    /// Multicast scouting (off by default: robots name their mapper).
    pub multicast_scouting: bool,
}

impl Default for SessionConfig {
    /// A client connecting to a mapper on this machine.
    fn default() -> Self {
        SessionConfig {
            mode: "client".into(),
            listen: Vec::new(),
            connect: vec!["tcp/127.0.0.1:7447".into()],
            multicast_scouting: false,
        }
    }
}

impl SessionConfig {
    /// A router listening on `endpoint` (the mapper's default).
    pub fn router(endpoint: &str) -> SessionConfig {
        SessionConfig {
            mode: "router".into(),
            listen: vec![endpoint.into()],
            connect: Vec::new(),
            multicast_scouting: false,
        }
    }

    /// A client of the router at `endpoint` (a robot's default).
    pub fn client(endpoint: &str) -> SessionConfig {
        SessionConfig {
            connect: vec![endpoint.into()],
            ..SessionConfig::default()
        }
    }

    /// This configuration as Zenoh's own.
    pub fn to_zenoh(&self) -> anyhow::Result<zenoh::Config> {
        let mut config = zenoh::Config::default();
        let values = [
            ("mode", serde_json::to_string(&self.mode)?),
            ("listen/endpoints", serde_json::to_string(&self.listen)?),
            ("connect/endpoints", serde_json::to_string(&self.connect)?),
            (
                "scouting/multicast/enabled",
                serde_json::to_string(&self.multicast_scouting)?,
            ),
            // Zenoh's default is 1 GiB: a peer could make us buffer that much per message.
            (
                "transport/link/rx/max_message_size",
                serde_json::to_string(&MAX_MESSAGE_BYTES)?,
            ),
        ];
        for (key, value) in values {
            config
                .insert_json5(key, &value)
                .map_err(|e| anyhow::anyhow!("zenoh config {key} = {value}: {e}"))?;
        }
        Ok(config)
    }

    /// Opens the session.
    pub async fn open(&self) -> anyhow::Result<zenoh::Session> {
        zenoh::open(self.to_zenoh()?)
            .await
            .map_err(|e| anyhow::anyhow!("zenoh session ({} mode): {e}", self.mode))
    }
}

/// Resolves when the process is asked to stop: Ctrl-C (SIGINT) or SIGTERM (`systemctl stop`,
/// `docker stop`, `kill`), so that the services stop the same way under a supervisor as in a
/// terminal.
pub async fn shutdown_signal() {
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut term) => {
                term.recv().await;
            }
            Err(e) => {
                // wire has no logger; this happens at start, where stderr is read.
                eprintln!(
                    "levelmap: SIGTERM cannot be handled ({e}); only Ctrl-C stops gracefully"
                );
                std::future::pending::<()>().await;
            }
        }
    };
    tokio::select! {
        _ = tokio::signal::ctrl_c() => {}
        _ = terminate => {}
    }
}
