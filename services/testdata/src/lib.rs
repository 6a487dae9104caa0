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
