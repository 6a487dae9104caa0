//! The programs the drills run from Debian packages (`ip`, `iptables`, `openssl`,
//! `systemd-analyze`): installed with apt-get when missing and the tests run as root, as CI
//! does; otherwise a test fails naming the package, never skips.

use std::path::Path;
use std::process::{Command, Stdio};

/// Whether the tests run as root (effective uid 0).
pub fn is_root() -> bool {
    let status = std::fs::read_to_string("/proc/self/status").expect("/proc/self/status");
    status
        .lines()
        .find_map(|l| l.strip_prefix("Uid:"))
        .and_then(|ids| ids.split_whitespace().nth(1))
        .is_some_and(|euid| euid == "0")
}

/// Makes sure each `(program, package)` runs: a missing one's package is installed when root
/// (under a lock: tests install in parallel), else the test fails naming it.
pub fn require(programs: &[(&str, &str)]) {
    let missing: Vec<_> = programs.iter().filter(|(p, _)| !found(p)).collect();
    if missing.is_empty() {
        return;
    }
    let packages: Vec<&str> = missing.iter().map(|(_, package)| *package).collect();
    assert!(
        is_root(),
        "the test needs {} (Debian: apt-get install {}); run as root to have it installed",
        missing
            .iter()
            .map(|(p, _)| *p)
            .collect::<Vec<_>>()
            .join(", "),
        packages.join(" ")
    );
    let lock = std::fs::File::create(std::env::temp_dir().join("levelmap-tests-apt.lock"))
        .expect("the apt lock file");
    lock.lock().expect("the apt lock");
    if missing.iter().all(|(p, _)| found(p)) {
        return; // Another test installed them meanwhile.
    }
    eprintln!("installing {} (apt-get)", packages.join(" "));
    let apt = |args: &[&str]| {
        let status = Command::new("apt-get")
            .args(args)
            .env("DEBIAN_FRONTEND", "noninteractive")
            .stdout(Stdio::null())
            .status()
            .unwrap_or_else(|e| panic!("apt-get: {e} (installing {})", packages.join(" ")));
        assert!(
            status.success(),
            "apt-get {} failed: the test needs {}",
            args.join(" "),
            packages.join(" ")
        );
    };
    apt(&["update", "-qq"]);
    apt(&[&["install", "-y", "-qq"][..], &packages].concat());
    for (program, package) in missing {
        assert!(
            found(program),
            "{package} installed, but `{program}` is not found"
        );
    }
}

/// Whether `program` is on the PATH or in the sbin folders (a root tool under sudo's PATH).
fn found(program: &str) -> bool {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .chain(["/usr/sbin", "/sbin"].map(Into::into))
        .any(|dir| is_executable(&dir.join(program)))
}

fn is_executable(path: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    path.metadata()
        .is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_program_on_the_path_is_found_and_a_missing_one_not() {
        assert!(found("sh"));
        assert!(!found("levelmap-no-such-program"));
    }
}
