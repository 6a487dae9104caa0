//! Readers and writers for the file formats of 2D SLAM: pose graphs (g2o, TORO) and laser
//! logs (CARMEN), and the Kümmerle et al. relations used to score maps. The only crate that
//! reads these files; the algorithms in `slam` stay free of I/O.

pub mod carmen;
pub mod posegraph;
pub mod relations;

use std::path::PathBuf;

/// Why a file could not be read. Every variant names the file; `Line` also the 1-based line.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The file could not be opened or read, or its compressed stream is corrupt or
    /// truncated.
    #[error("{}: {error}", path.display())]
    Io {
        path: PathBuf,
        /// The cause, already in the message (not a chained source, so it prints once).
        error: std::io::Error,
    },
    /// A line is malformed.
    #[error("{}:{line}: {message}", path.display())]
    Line {
        path: PathBuf,
        line: usize,
        message: String,
    },
    /// The file as a whole is unusable (empty, no element of the expected kind, …).
    #[error("{}: {message}", path.display())]
    Invalid { path: PathBuf, message: String },
}
