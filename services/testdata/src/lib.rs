//! Where the tests and benchmarks find the public test data: `$LEVELMAP_DATA`, or
//! `../shared/data` beside the repository. Dev-only: no production crate depends on it, since
//! it panics by design.

use std::path::PathBuf;

/// The variable that overrides the data folder.
pub const ENV: &str = "LEVELMAP_DATA";

/// The data folder: `$LEVELMAP_DATA` if set, else `../shared/data` beside the repository.
pub fn root() -> PathBuf {
    std::env::var_os(ENV)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"))
}

/// A path in the public test data: `$LEVELMAP_DATA/relative`, or `../shared/data/relative`
/// beside the repository. Panics, naming the path, if it does not exist: tests and benchmarks
/// that need the data must fail loudly without it, never skip.
pub fn shared_data(relative: &str) -> PathBuf {
    let path = root().join(relative);
    assert!(
        path.exists(),
        "test data missing: {} (set {ENV} or put ../shared beside the repository)",
        path.display()
    );
    path
}

/// What the cross-implementation tests check levelmap against, from PyPI: rosbags (CDR, MCAP,
/// rosbag2) and the Python Zenoh (live rmw_zenoh keys) for ROS 2; the MCAP reference reader
/// with its protobuf decoder for `levelmap record`'s files; rasterio (GDAL and PROJ in its
/// wheel) for the GeoTIFF and the web tiles.
pub const REFERENCE_PYTHON: [&str; 7] = [
    "rosbags==0.11.9",
    "eclipse-zenoh==1.10.2",
    "numpy",
    "mcap==1.6.0",
    "mcap-protobuf-support==0.6.0",
    "protobuf==7.36.2",
    "rasterio==1.4.4",
];

/// A python with [`REFERENCE_PYTHON`]: a venv made on first use beside the build
/// (`target/reference-python-venv-3`; the number changes with the list). Panics, naming the step, when python3 or PyPI is missing:
/// the tests that need it must fail, not skip.
pub fn reference_python() -> PathBuf {
    let exe = std::env::current_exe().expect("the test's path");
    // target/<profile>/deps/<test>: the venv goes in target/.
    let target = exe
        .ancestors()
        .nth(3)
        .expect("a test runs from target/<profile>/deps");
    let venv = target.join("reference-python-venv-3");
    let python = venv.join("bin/python");
    // Tests run in parallel, and in several processes: one makes the venv, the others wait.
    let lock = std::fs::File::create(target.join("reference-python-venv-3.lock"))
        .expect("a lock file beside the build");
    lock.lock().expect("the venv's lock");
    // Written last: a venv whose install failed half-way is made again.
    let ready = venv.join("installed");
    if !ready.exists() {
        let run = |cmd: &mut std::process::Command| {
            let status = cmd.status().expect("python3 runs");
            assert!(
                status.success(),
                "{cmd:?} failed: the test needs python3 and PyPI"
            );
        };
        run(std::process::Command::new("python3")
            .args(["-m", "venv", "--clear"])
            .arg(&venv));
        run(std::process::Command::new(venv.join("bin/pip"))
            .args(["install", "-q"])
            .args(REFERENCE_PYTHON));
        std::fs::write(&ready, REFERENCE_PYTHON.join("\n")).expect("the venv's marker");
    }
    python
}

/// Runs `script` with `args` in [`reference_python`]'s python: its stdout. Panics with its
/// stderr when it fails.
pub fn run_reference_python<S: AsRef<std::ffi::OsStr>>(
    script: &std::path::Path,
    args: &[S],
) -> String {
    let out = std::process::Command::new(reference_python())
        .arg(script)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{}: {e}", script.display()));
    assert!(
        out.status.success(),
        "{}: {}",
        script.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_file_names_its_path_and_the_override() {
        let err = std::panic::catch_unwind(|| shared_data("no/such/file.bin")).unwrap_err();
        let message = err.downcast_ref::<String>().expect("a formatted message");
        assert!(
            message.contains("no/such/file.bin") && message.contains(ENV),
            "{message}"
        );
    }
}
