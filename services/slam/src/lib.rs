//! The mapping core of levelmap, after the scan-based SLAM of Wulf, Brenneke and Wagner
//! (section 4): nodes are collection positions, edges are odometry, scan matches (IDC) and
//! GPS fixes; the network is solved as full nonlinear least squares on SE(2) (beyond the
//! paper's linear solution). Pure library: no I/O, no async.
//!
//! The `solver` feature (default) adds everything that needs faer: the sparse linear algebra,
//! the optimizer, chordal initialization and 2D mapping. Without it (`default-features =
//! false`) the crate is the pure geometry a robot needs: poses, geodesy, the GPS fix model
//! ([`gnss`]), the network's types, scan matching and the occupancy grid.

// Needs no faer.
pub mod geodesy;
pub mod gnss;
pub mod grid;
pub mod localize;
pub mod matching;
pub mod network;
pub mod parts;
pub mod robust;
pub mod se2;
pub mod smoother;
mod splitmix;

pub use gnss::GpsObservation;
pub use grid::{BeamFan, CellState, FanBeam, GridError, GridParams, OccupancyGrid};
pub use nalgebra;
pub use network::{EdgeKind, GpsEdge, GraphError, PoseGraph, RelativeEdge};
pub use parts::PartTracker;
pub use robust::Robust;
pub use se2::{Pose2, aligned_position_rmse, position_rmse, rigid_fit, wrap_angle};
pub use smoother::{IncrementalSmoother, SmootherError, SmootherParams, TreeShape, UpdateStats};

// The solver: faer's sparse Cholesky and everything built on it.
#[cfg(feature = "solver")]
pub mod incremental;
#[cfg(feature = "solver")]
pub mod init;
#[cfg(feature = "solver")]
pub mod linear;
#[cfg(feature = "solver")]
pub mod mapping2d;
#[cfg(feature = "solver")]
pub mod optimize;

#[cfg(feature = "solver")]
pub use init::{Init, InitError, initialize};
#[cfg(feature = "solver")]
pub use mapping2d::{
    BackgroundSolve, ConsistencyParams, ContactCheckParams, CoverageParams, FirstContactParams,
    Mapper2d, Mapper2dParams, MapperStats, Passed, Placed, RestoreError, SavedMapper,
    SolvedInBackground, SubmapSearchParams, WrongClosures, WrongMatches,
};
#[cfg(feature = "solver")]
pub use optimize::{Method, OptimizeParams, OptimizeReport, Optimizer, StopReason};
