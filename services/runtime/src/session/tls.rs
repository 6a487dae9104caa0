//! The check of the effective TLS settings at start: they hold together, and every file they
//! name is readable PEM of the right kind.

use super::{TLS, get};
use anyhow::{anyhow, bail};
use rustls_pki_types::pem::{self, PemObject};
use rustls_pki_types::{CertificateDer, PrivateKeyDer};
use std::path::Path;

/// The effective TLS settings hold together and every file they name is readable PEM of the
/// right kind; `origin` names where a key was set. Zenoh would only find out when a link
/// opens, and a robot retries its link forever.
pub(super) fn check_tls(
    config: &zenoh::Config,
    origin: &dyn Fn(&str) -> String,
) -> anyhow::Result<()> {
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
