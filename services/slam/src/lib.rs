//! The mapping core of levelmap, after the scan-based SLAM of Wulf, Brenneke and Wagner
//! (section 4): nodes are collection positions, edges are odometry, scan matches (IDC) and
//! GPS fixes; the network is solved as full nonlinear least squares on SE(2) (beyond the
//! paper's linear solution). Pure library: no I/O, no async.

pub mod geodesy;
pub mod gnss;
pub mod grid;
pub mod init;
pub mod linear;
pub mod mapping2d;
pub mod matching;
pub mod network;
pub mod optimize;
pub mod robust;
pub mod se2;

pub use grid::{CellState, GridError, GridParams, OccupancyGrid};
pub use init::{Init, InitError, initialize};
pub use mapping2d::{GpsObservation, Mapper2d, Mapper2dParams, MapperStats, Placed};
pub use nalgebra;
pub use network::{EdgeKind, GpsEdge, GraphError, PoseGraph, RelativeEdge};
pub use optimize::{Method, OptimizeParams, OptimizeReport, Optimizer, StopReason};
pub use robust::Robust;
pub use se2::{Pose2, position_rmse, wrap_angle};
