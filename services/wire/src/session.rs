//! The Zenoh session of a levelmap service: mode, endpoints and TLS from the service's config
//! file, over an optional Zenoh configuration file (access control and the rest); the config
//! loader both services share ([`load_toml`], with [`mod@env`] overrides).

use anyhow::{anyhow, bail};
use rustls_pki_types::pem::{self, PemObject};
use rustls_pki_types::{CertificateDer, PrivateKeyDer};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
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
        check_tls(&config, &origin)?;
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

/// The effective TLS settings hold together and every file they name is readable PEM of the
/// right kind; `origin` names where a key was set. Zenoh would only find out when a link
/// opens, and a robot retries its link forever.
fn check_tls(config: &zenoh::Config, origin: &dyn Fn(&str) -> String) -> anyhow::Result<()> {
    let path = |key: &str| -> anyhow::Result<Option<String>> {
        Ok(serde_json::from_str(&get(
            config,
            &format!("{TLS}/{key}"),
        )?)?)
    };
    for (key, is_key) in [
        ("root_ca_certificate", false),
        ("listen_certificate", false),
        ("listen_private_key", true),
        ("connect_certificate", false),
        ("connect_private_key", true),
    ] {
        if let Some(file) = path(key)? {
            check_pem(Path::new(&file), is_key)
                .map_err(|e| anyhow!("{}: {file}: {e}", origin(key)))?;
        }
    }
    let mtls: Option<bool> = serde_json::from_str(&get(config, &format!("{TLS}/enable_mtls"))?)?;
    let mtls = mtls.unwrap_or(false);
    let root_ca = path("root_ca_certificate")?;
    for (side, cert, key) in [
        ("listen", "listen_certificate", "listen_private_key"),
        ("connect", "connect_certificate", "connect_private_key"),
    ] {
        let (has_cert, has_key) = (path(cert)?.is_some(), path(key)?.is_some());
        if has_cert != has_key {
            let (set, unset) = if has_cert { (cert, key) } else { (key, cert) };
            bail!("{} is set without {TLS}/{unset}", origin(set));
        }
        let Some(endpoint) = tls_endpoint(config, &format!("{side}/endpoints"))? else {
            continue;
        };
        // A listener always needs its own certificate; a client only for mutual TLS.
        if !has_cert && (side == "listen" || mtls) {
            bail!(
                "{side} endpoint {endpoint} needs a certificate and key: [zenoh.tls] cert and \
                 key, or {TLS}/{cert} and {key} in the config file"
            );
        }
        if side == "listen" && mtls && root_ca.is_none() {
            bail!(
                "listen endpoint {endpoint} with mutual TLS needs the CA of the clients' \
                 certificates: [zenoh.tls] root_ca, or {TLS}/root_ca_certificate"
            );
        }
    }
    Ok(())
}

/// The first `tls/` endpoint under `key` (a list, or lists per mode).
fn tls_endpoint(config: &zenoh::Config, key: &str) -> anyhow::Result<Option<String>> {
    fn find(value: &serde_json::Value) -> Option<String> {
        match value {
            serde_json::Value::String(s) if s.starts_with("tls/") => Some(s.clone()),
            serde_json::Value::Array(items) => items.iter().find_map(find),
            serde_json::Value::Object(fields) => fields.values().find_map(find),
            _ => None,
        }
    }
    Ok(find(&serde_json::from_str(&get(config, key)?)?))
}

/// `path` is readable and holds PEM certificates (or, with `is_key`, a PEM private key, in a
/// form Zenoh reads: PKCS#8, PKCS#1 or SEC1).
fn check_pem(path: &Path, is_key: bool) -> Result<(), String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read it ({e})"))?;
    let pem_error = |e: pem::Error| match e {
        pem::Error::MissingSectionEnd { .. } => "bad PEM: a section has no END line".to_owned(),
        pem::Error::IllegalSectionStart { .. } => "bad PEM: a malformed BEGIN line".to_owned(),
        pem::Error::Base64Decode(e) => format!("bad PEM: {e}"),
        e => format!("bad PEM: {e}"),
    };
    if is_key {
        return match PrivateKeyDer::from_pem_slice(&bytes) {
            Ok(_) => Ok(()),
            Err(pem::Error::NoItemsFound) => {
                Err("no private key in it (PEM: PKCS#8, PKCS#1 or SEC1)".to_owned())
            }
            Err(e) => Err(pem_error(e)),
        };
    }
    let certs = CertificateDer::pem_slice_iter(&bytes)
        .collect::<Result<Vec<_>, _>>()
        .map_err(pem_error)?;
    if certs.is_empty() {
        return Err("no certificate in it (PEM)".to_owned());
    }
    Ok(())
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

#[cfg(test)]
mod tests {
    use super::*;

    // Well-formed PEM around meaningless bytes: what is checked at start is the files, not
    // the cryptography (rustls does that when a link opens).
    const CERT: &str =
        "-----BEGIN CERTIFICATE-----\nMIIBozCCAUmgAwIBAgIU\n-----END CERTIFICATE-----\n";
    const KEY: &str =
        "-----BEGIN PRIVATE KEY-----\nMIGHAgEAMBMGByqGSM49\n-----END PRIVATE KEY-----\n";

    struct Dir(PathBuf);

    impl Dir {
        fn new(name: &str) -> Dir {
            let dir =
                std::env::temp_dir().join(format!("wire-session-{name}-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).unwrap();
            Dir(dir)
        }

        fn file(&self, name: &str, text: &str) -> PathBuf {
            let path = self.0.join(name);
            std::fs::write(&path, text).unwrap();
            path
        }
    }

    impl Drop for Dir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    fn value(config: &zenoh::Config, key: &str) -> serde_json::Value {
        serde_json::from_str(&config.get_json(key).unwrap()).unwrap()
    }

    fn error(config: &SessionConfig, role: Role) -> String {
        let e = config.to_zenoh(role).expect_err("a bad setting is refused");
        let message = format!("{e:#}");
        assert!(!message.contains('\n'), "one line: {message}");
        message
    }

    #[test]
    fn unset_keys_take_the_defaults_of_the_role() {
        let router = SessionConfig::default().to_zenoh(Role::Router).unwrap();
        assert_eq!(value(&router, "mode"), "router");
        assert_eq!(
            value(&router, "listen/endpoints"),
            serde_json::json!(["tcp/0.0.0.0:7447"])
        );
        assert_eq!(value(&router, "connect/endpoints"), serde_json::json!([]));
        assert_eq!(value(&router, "scouting/multicast/enabled"), false);
        let client = SessionConfig::default().to_zenoh(Role::Client).unwrap();
        assert_eq!(value(&client, "mode"), "client");
        assert_eq!(
            value(&client, "connect/endpoints"),
            serde_json::json!(["tcp/127.0.0.1:7447"])
        );
        assert_eq!(value(&client, "scouting/multicast/enabled"), false);
        assert_eq!(
            value(&client, "transport/link/rx/max_message_size"),
            MAX_MESSAGE_BYTES
        );
        // No TLS unless asked for.
        assert_eq!(
            value(&client, "transport/link/tls/enable_mtls"),
            serde_json::Value::Null
        );
    }

    #[test]
    fn the_deploy_files_state_the_session_defaults_in_their_comments() {
        for (file, role) in [("edge.toml", Role::Client), ("mapper.toml", Role::Router)] {
            let path = Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../deploy")
                .join(file);
            let text = std::fs::read_to_string(&path).unwrap();
            // The [zenoh] table with its commented session keys set as written.
            let mut section = "";
            let stated: String = text
                .lines()
                .map(|line| {
                    if line.starts_with('[') {
                        section = line;
                    }
                    let key = line.trim_start_matches("# ").split(" = ").next().unwrap();
                    let session_key =
                        ["mode", "listen", "connect", "multicast_scouting"].contains(&key);
                    match line.strip_prefix("# ") {
                        Some(setting) if section == "[zenoh]" && session_key => setting,
                        _ => line,
                    }
                })
                .collect::<Vec<_>>()
                .join("\n");
            let table: toml::Table = toml::from_str(&stated).unwrap();
            let stated: SessionConfig = table["zenoh"].clone().try_into().unwrap();
            assert!(
                stated.mode.is_some() && stated.multicast_scouting.is_some(),
                "{file}"
            );
            let (stated, default) = (
                stated.to_zenoh(role).unwrap(),
                SessionConfig::default().to_zenoh(role).unwrap(),
            );
            for key in [
                "mode",
                "listen/endpoints",
                "connect/endpoints",
                "scouting/multicast/enabled",
            ] {
                assert_eq!(value(&stated, key), value(&default, key), "{file}: {key}");
            }
        }
    }

    #[test]
    fn the_file_sets_what_the_table_leaves_unset_and_the_table_wins() {
        let dir = Dir::new("merge");
        let file = dir.file(
            "zenoh.json5",
            r#"{ mode: "router", listen: { endpoints: ["tcp/127.0.0.1:7999"] },
                 scouting: { multicast: { enabled: true } }, queries_default_timeout: 1234 }"#,
        );
        let from_file = SessionConfig {
            config_file: Some(file.clone()),
            ..SessionConfig::default()
        };
        // The file's mode beats the role's; a router's connect default follows.
        let config = from_file.to_zenoh(Role::Client).unwrap();
        assert_eq!(value(&config, "mode"), "router");
        assert_eq!(
            value(&config, "listen/endpoints"),
            serde_json::json!(["tcp/127.0.0.1:7999"])
        );
        assert_eq!(value(&config, "connect/endpoints"), serde_json::json!([]));
        assert_eq!(value(&config, "scouting/multicast/enabled"), true);
        assert_eq!(value(&config, "queries_default_timeout"), 1234);

        let over = SessionConfig {
            mode: Some("peer".into()),
            listen: Some(vec!["tcp/127.0.0.1:7000".into()]),
            multicast_scouting: Some(false),
            ..from_file
        };
        let config = over.to_zenoh(Role::Client).unwrap();
        assert_eq!(value(&config, "mode"), "peer");
        assert_eq!(
            value(&config, "listen/endpoints"),
            serde_json::json!(["tcp/127.0.0.1:7000"])
        );
        assert_eq!(value(&config, "scouting/multicast/enabled"), false);
        assert_eq!(value(&config, "queries_default_timeout"), 1234);
    }

    #[test]
    fn tls_files_become_zenoh_keys_with_mutual_tls() {
        let dir = Dir::new("tls");
        let tls = TlsConfig {
            root_ca: Some(dir.file("ca.pem", CERT)),
            cert: Some(dir.file("me.pem", CERT)),
            key: Some(dir.file("me.key", KEY)),
        };
        let config = SessionConfig {
            listen: Some(vec!["tls/127.0.0.1:7447".into()]),
            tls: tls.clone(),
            ..SessionConfig::default()
        }
        .to_zenoh(Role::Router)
        .unwrap();
        let path = |p: &Option<PathBuf>| serde_json::json!(p.as_ref().unwrap().to_str().unwrap());
        for (key, file) in [
            ("root_ca_certificate", &tls.root_ca),
            ("listen_certificate", &tls.cert),
            ("connect_certificate", &tls.cert),
            ("listen_private_key", &tls.key),
            ("connect_private_key", &tls.key),
        ] {
            assert_eq!(value(&config, &format!("{TLS}/{key}")), path(file), "{key}");
        }
        assert_eq!(value(&config, &format!("{TLS}/enable_mtls")), true);
    }

    #[test]
    fn a_bad_tls_setting_is_one_line_naming_the_key_and_file() {
        let dir = Dir::new("bad");
        let (ca, cert, key) = (
            dir.file("ca.pem", CERT),
            dir.file("me.pem", CERT),
            dir.file("me.key", KEY),
        );
        let with = |root_ca: &Path, cert: &Path, key: &Path| SessionConfig {
            connect: Some(vec!["tls/127.0.0.1:7447".into()]),
            tls: TlsConfig {
                root_ca: Some(root_ca.into()),
                cert: Some(cert.into()),
                key: Some(key.into()),
            },
            ..SessionConfig::default()
        };
        let missing = dir.0.join("missing.pem");
        let e = error(&with(&ca, &missing, &key), Role::Client);
        assert!(
            e.starts_with("[zenoh.tls] cert: ") && e.contains(&*missing.to_string_lossy()),
            "{e}"
        );
        assert!(e.contains("cannot read it"), "{e}");

        let e = error(&with(&ca, &cert, &cert), Role::Client);
        assert!(
            e.starts_with("[zenoh.tls] key: ") && e.contains("no private key"),
            "{e}"
        );
        let garbage = dir.file("garbage.pem", "not a certificate\n");
        let e = error(&with(&garbage, &cert, &key), Role::Client);
        assert!(
            e.starts_with("[zenoh.tls] root_ca: ") && e.contains("no certificate"),
            "{e}"
        );
        let cut = dir.file("cut.pem", &CERT[..CERT.len() - 30]);
        let e = error(&with(&ca, &cut, &key), Role::Client);
        assert!(e.contains("cut.pem: bad PEM"), "{e}");

        let half = SessionConfig {
            tls: TlsConfig {
                cert: Some(cert.clone()),
                ..TlsConfig::default()
            },
            ..SessionConfig::default()
        };
        assert_eq!(
            error(&half, Role::Client),
            "[zenoh.tls] cert is set without key"
        );

        let bare = SessionConfig {
            listen: Some(vec!["tls/0.0.0.0:7447".into()]),
            ..SessionConfig::default()
        };
        let e = error(&bare, Role::Router);
        assert!(
            e.starts_with("listen endpoint tls/0.0.0.0:7447 needs a certificate and key"),
            "{e}"
        );
        let no_ca = SessionConfig {
            tls: TlsConfig {
                root_ca: None,
                ..with(&ca, &cert, &key).tls
            },
            ..bare
        };
        let e = error(&no_ca, Role::Router);
        assert!(e.contains("mutual TLS needs the CA"), "{e}");

        // Keys set in the config file are named with the file.
        let file = dir.file(
            "zenoh.json5",
            &format!(
                r#"{{ transport: {{ link: {{ tls: {{ listen_certificate: "{}", listen_private_key: "{}" }} }} }} }}"#,
                missing.display(),
                key.display()
            ),
        );
        let from_file = SessionConfig {
            config_file: Some(file.clone()),
            ..SessionConfig::default()
        };
        let e = error(&from_file, Role::Router);
        assert!(
            e.starts_with(&format!(
                "{TLS}/listen_certificate in {}: {}",
                file.display(),
                missing.display()
            )),
            "{e}"
        );
        let e = error(
            &SessionConfig {
                config_file: Some(dir.0.join("none.json5")),
                ..SessionConfig::default()
            },
            Role::Router,
        );
        assert!(
            e.starts_with("[zenoh] config_file ") && e.contains("none.json5"),
            "{e}"
        );
        let broken = dir.file("broken.json5", "{ mode: \"router\",\n");
        let e = error(
            &SessionConfig {
                config_file: Some(broken),
                ..SessionConfig::default()
            },
            Role::Router,
        );
        assert!(
            e.starts_with("[zenoh] config_file ") && !e.contains(".rs:"),
            "{e}"
        );
        let typo = SessionConfig {
            mode: Some("routr".into()),
            ..SessionConfig::default()
        };
        assert_eq!(
            error(&typo, Role::Router),
            r#"[zenoh] mode "routr": one of "router", "peer", "client""#
        );
    }
}
