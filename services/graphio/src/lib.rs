//! Readers and writers for the file formats of 2D SLAM: pose graphs (g2o, TORO) and laser
//! logs (CARMEN), and the Kümmerle et al. relations used to score maps. The only crate that
//! reads these files; the algorithms in `slam` stay free of I/O.
//!
//! The map products (docs/slam.md, "Map products") are encoded here too, to bytes or text and
//! never to a file, so the command line and the HTTP API serve the same bytes: the occupancy
//! grid as PNG and as PGM + YAML for ROS map_server ([`gridmap`]), nodes and trajectories as
//! GeoJSON ([`geojson`]), the grid on the Earth as a GeoTIFF ([`georaster`]) and as XYZ web
//! tiles ([`webtiles`]), trajectories as TUM text ([`trajectory`]), the graph as g2o
//! ([`posegraph::to_g2o`]).

pub mod carmen;
pub mod geojson;
pub mod georaster;
pub mod gridmap;
pub mod posegraph;
pub mod relations;
pub mod trajectory;
pub mod webtiles;

use std::path::PathBuf;

/// Why a file could not be read. Every variant names the file; `Line` also the 1-based line.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The file could not be opened or read, or its compressed stream is corrupt or
    /// truncated.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause, already in the message (not a chained source, so it prints once).
        error: std::io::Error,
    },
    /// A line is malformed.
    #[error("{}:{line}: {message}", path.display())]
    Line {
        /// The file.
        path: PathBuf,
        /// The 1-based line.
        line: usize,
        /// What is wrong with it.
        message: String,
    },
    /// The file as a whole is unusable (empty, no element of the expected kind, …).
    #[error("{}: {message}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
}

/// Why a map product could not be encoded. Never a panic, whatever the input's fields hold.
#[derive(Debug, thiserror::Error)]
pub enum EncodeError {
    /// The grid has no cell, its `cells` do not match `width × height`, or its cell size or
    /// origin is not a finite place.
    #[error(
        "grid of {width} × {height} cells holding {cells} cell values, or not placed (cell size, origin)"
    )]
    BadGrid {
        /// Cells across (x).
        width: usize,
        /// Cells up (y).
        height: usize,
        /// Cell values it holds.
        cells: usize,
    },
    /// The grid is wider or higher than an image can be (2³¹ − 1 pixels for PNG).
    #[error("grid of {width} × {height} cells is too large for an image")]
    GridTooLarge {
        /// Cells across (x).
        width: usize,
        /// Cells up (y).
        height: usize,
    },
    /// Pose `index` (in input order) has a NaN or infinite component.
    #[error("pose {index} is not finite")]
    NonFinitePose {
        /// Index of the pose.
        index: usize,
    },
    /// The PNG encoder failed.
    #[error("PNG encoding: {0}")]
    Png(String),
}
