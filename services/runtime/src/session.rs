//! The Zenoh session of a levelmap service: mode, endpoints and TLS from the service's config
//! file, over an optional Zenoh configuration file (access control and the rest); the config
//! loader every service shares is `settings`' ([`load_toml`], with [`mod@env`] overrides),
//! re-exported here.

use anyhow::{anyhow, bail};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::PathBuf;
use std::time::{SystemTime, UNIX_EPOCH};

/// Wall-clock time in ns since the Unix epoch, as the wire's stamps are.
pub fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

pub use settings::{env, load_toml, load_toml_with};
mod tls;

/// The largest Zenoh message a levelmap session takes: twice the largest valid node
/// ([`wire::MAX_NODE_BYTES`]), so every valid node fits with room for its framing.
pub const MAX_MESSAGE_BYTES: usize = 2 * wire::MAX_NODE_BYTES;

/// Which service a session belongs to: what it is when neither its TOML nor its
/// `config_file` sets `mode`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// A robot's edge service: a client of the mapper's router.
    Client,
    /// The mapper: the router robots connect to.
    Router,
}

impl Role {
    fn mode(self) -> &'static str {
        match self {
            Role::Client => "client",
            Role::Router => "router",
        }
    }
}

/// Where the mapper's router listens when nothing else says.
pub const DEFAULT_ROUTER_LISTEN: &str = "tcp/0.0.0.0:7447";
/// Where a client connects when nothing else says: a mapper on this machine.
pub const DEFAULT_CLIENT_CONNECT: &str = "tcp/127.0.0.1:7447";

/// A service's Zenoh session (`[zenoh]` in `edge.toml` and `mapper.toml`). The four session
/// keys mirror Zenoh's own (`mode`, `listen/endpoints`, `connect/endpoints`,
/// `scouting/multicast/enabled`). Each is taken, in order, from this table, else from
/// `config_file`, else from the default: `mode` from the service's [`Role`], `listen`
/// [`DEFAULT_ROUTER_LISTEN`] for a router (nothing otherwise), `connect`
/// [`DEFAULT_CLIENT_CONNECT`] for a client (nothing otherwise), multicast scouting off.
/// A key the file leaves at Zenoh's own default counts as unset there. Zenoh's
/// `transport/link/rx/max_message_size` is [`MAX_MESSAGE_BYTES`] unless the file sets it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SessionConfig {
    /// `router`, `peer` or `client`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mode: Option<String>,
    /// Endpoints to listen on, e.g. `tcp/0.0.0.0:7447`, `tls/0.0.0.0:7447`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub listen: Option<Vec<String>>,
    /// Endpoints to connect to, e.g. `tcp/mapper.local:7447`, `tls/mapper.local:7447`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub connect: Option<Vec<String>>,
    /// Multicast scouting (off by default: robots name their mapper).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub multicast_scouting: Option<bool>,
    /// A Zenoh configuration file in Zenoh's own format (JSON5, as `zenohd -c` reads), for
    /// what this table has no key for: access control, TLS options, timeouts. This table's
    /// keys are laid over it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub config_file: Option<PathBuf>,
    /// Certificates for `tls/` endpoints.
    pub tls: TlsConfig,
}

/// `[zenoh.tls]`: PEM files for `tls/` endpoints, each overriding the matching key of
/// Zenoh's `transport/link/tls` (paths relative to the working directory).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TlsConfig {
    /// The certificate authority that signed the other side's certificate
    /// (`root_ca_certificate`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub root_ca: Option<PathBuf>,
    /// This side's certificate chain: `listen_certificate` and `connect_certificate`. With
    /// `key`, mutual TLS is on (`enable_mtls`): a listener requires a certificate signed by
    /// `root_ca` from every client, and a client presents this one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cert: Option<PathBuf>,
    /// The private key of `cert`: `listen_private_key` and `connect_private_key`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub key: Option<PathBuf>,
}

impl SessionConfig {
    /// A router listening on `endpoint` (the mapper's default).
    pub fn router(endpoint: &str) -> SessionConfig {
        SessionConfig {
            mode: Some("router".into()),
            listen: Some(vec![endpoint.into()]),
            connect: Some(Vec::new()),
            multicast_scouting: Some(false),
            ..SessionConfig::default()
        }
    }

    /// A client of the router at `endpoint` (a robot's default).
    pub fn client(endpoint: &str) -> SessionConfig {
        SessionConfig {
            mode: Some("client".into()),
            listen: Some(Vec::new()),
            connect: Some(vec![endpoint.into()]),
            multicast_scouting: Some(false),
            ..SessionConfig::default()
        }
    }

    /// This configuration as Zenoh's own, for a session of `role`: `config_file`, this
    /// table's keys over it, the defaults for what neither sets. Every TLS file is read and
    /// parsed here, so that a bad one stops the service at start naming the file.
    pub fn to_zenoh(&self, role: Role) -> anyhow::Result<zenoh::Config> {
        let mut config = match &self.config_file {
            Some(path) => zenoh::Config::from_file(path)
                .map_err(|e| anyhow!("[zenoh] config_file {}: {}", path.display(), one_line(e)))?,
            None => zenoh::Config::default(),
        };
        let zenoh_default = zenoh::Config::default();
        let file_sets = |config: &zenoh::Config, key: &str| {
            self.config_file.is_some()
                && config.get_json(key).ok() != zenoh_default.get_json(key).ok()
        };

        if let Some(mode) = &self.mode
            && !["router", "peer", "client"].contains(&mode.as_str())
        {
            bail!("[zenoh] mode {mode:?}: one of \"router\", \"peer\", \"client\"");
        }
        let mode = match (&self.mode, file_sets(&config, "mode")) {
            (Some(mode), _) => Some(mode.clone()),
            (None, true) => None,
            (None, false) => Some(role.mode().to_owned()),
        };
        if let Some(mode) = &mode {
            insert(&mut config, "mode", mode)?;
        }
        let mode: String = serde_json::from_str(&get(&config, "mode")?)?;
        let default_listen = match mode.as_str() {
            "router" => vec![DEFAULT_ROUTER_LISTEN.to_owned()],
            _ => Vec::new(),
        };
        let default_connect = match mode.as_str() {
            "client" => vec![DEFAULT_CLIENT_CONNECT.to_owned()],
            _ => Vec::new(),
        };
        let layers = [
            (
                "listen/endpoints",
                self.listen.as_ref().map(json),
                json(&default_listen),
            ),
            (
                "connect/endpoints",
                self.connect.as_ref().map(json),
                json(&default_connect),
            ),
            (
                "scouting/multicast/enabled",
                self.multicast_scouting.as_ref().map(json),
                json(&false),
            ),
            // Zenoh's default is 1 GiB: a peer could make us buffer that much per message.
            // No TOML key: only a config_file that sets it otherwise changes it.
            (
                "transport/link/rx/max_message_size",
                None,
                json(&MAX_MESSAGE_BYTES),
            ),
        ];
        for (key, ours, default) in layers {
            match ours {
                Some(value) => insert_json(&mut config, key, &value)?,
                None if !file_sets(&config, key) => insert_json(&mut config, key, &default)?,
                None => {}
            }
        }

        // [zenoh.tls] over the file's transport/link/tls; errors name where each key was set.
        let mut from_table = HashMap::new();
        let tls = &self.tls;
        for (name, path, keys) in [
            ("root_ca", &tls.root_ca, &["root_ca_certificate"][..]),
            (
                "cert",
                &tls.cert,
                &["listen_certificate", "connect_certificate"][..],
            ),
            (
                "key",
                &tls.key,
                &["listen_private_key", "connect_private_key"][..],
            ),
        ] {
            let Some(path) = path else { continue };
            for &key in keys {
                insert(
                    &mut config,
                    &format!("{TLS}/{key}"),
                    &path.to_string_lossy(),
                )?;
                from_table.insert(key, format!("[zenoh.tls] {name}"));
            }
        }
        match (&tls.cert, &tls.key) {
            (Some(_), Some(_)) => insert_json(&mut config, &format!("{TLS}/enable_mtls"), "true")?,
            (Some(_), None) => bail!("[zenoh.tls] cert is set without key"),
            (None, Some(_)) => bail!("[zenoh.tls] key is set without cert"),
            (None, None) => {}
        }
        let origin = |key: &str| match (from_table.get(key), &self.config_file) {
            (Some(name), _) => name.clone(),
            (None, Some(file)) => format!("{TLS}/{key} in {}", file.display()),
            (None, None) => format!("{TLS}/{key}"),
        };
        tls::check_tls(&config, &origin)?;
        Ok(config)
    }

    /// Opens the session of a service of `role` (see [`SessionConfig::to_zenoh`]).
    pub async fn open(&self, role: Role) -> anyhow::Result<zenoh::Session> {
        let config = self.to_zenoh(role)?;
        let mode = get(&config, "mode").unwrap_or_default();
        zenoh::open(config).await.map_err(|e| {
            anyhow!(
                "zenoh session ({} mode): {}",
                mode.trim_matches('"'),
                one_line(e)
            )
        })
    }
}

/// Zenoh's TLS link settings.
const TLS: &str = "transport/link/tls";

fn json<T: Serialize + ?Sized>(value: &T) -> String {
    serde_json::to_string(value).expect("strings, lists and booleans serialize")
}

fn insert_json(config: &mut zenoh::Config, key: &str, value: &str) -> anyhow::Result<()> {
    config
        .insert_json5(key, value)
        .map_err(|e| anyhow!("zenoh config {key} = {value}: {}", one_line(e)))
}

fn insert(config: &mut zenoh::Config, key: &str, value: &str) -> anyhow::Result<()> {
    insert_json(config, key, &json(value))
}

fn get(config: &zenoh::Config, key: &str) -> anyhow::Result<String> {
    config
        .get_json(key)
        .map_err(|e| anyhow!("zenoh config {key}: {e}"))
}

/// A Zenoh error on one line, without the source location Zenoh appends (" at
/// /…/file.rs:N.").
fn one_line(e: impl std::fmt::Display) -> String {
    let text = e
        .to_string()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    match text.rfind(" at ") {
        Some(at) if text.ends_with('.') && text[at..].contains(".rs:") => text[..at].to_owned(),
        _ => text,
    }
}

/// Resolves when the process is asked to stop: Ctrl-C (SIGINT) or SIGTERM (`systemctl stop`,
/// `docker stop`, `kill`), so that the services stop the same way under a supervisor as in a
/// terminal. The signals are caught from this call on, not from the first poll: a service
/// calls it before it starts serving, so a stop that comes while it starts is graceful too
/// (caught only once awaited, a SIGTERM right after the HTTP API answered killed the mapper
/// in a CI run). Call it within the Tokio runtime.
pub fn shutdown_signal() -> impl std::future::Future<Output = ()> + Send + 'static {
    use tokio::signal::unix::{SignalKind, signal};
    let caught = |kind: SignalKind, name: &str| {
        signal(kind)
            .inspect_err(|e| {
                // runtime has no logger; this happens at start, where stderr is read.
                eprintln!("levelmap: {name} cannot be handled ({e}); it stops the process at once");
            })
            .ok()
    };
    let (mut term, mut interrupt) = (
        caught(SignalKind::terminate(), "SIGTERM"),
        caught(SignalKind::interrupt(), "SIGINT"),
    );
    async move {
        tokio::select! {
            _ = received(&mut term) => {}
            _ = received(&mut interrupt) => {}
        }
    }
}

/// Resolves when `signal` comes; never if it could not be caught.
async fn received(signal: &mut Option<tokio::signal::unix::Signal>) {
    match signal {
        Some(signal) => {
            signal.recv().await;
        }
        None => std::future::pending().await,
    }
}

#[cfg(test)]
mod tests;
