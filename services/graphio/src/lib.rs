//! Readers and writers for the file formats of 2D SLAM: pose graphs (g2o, TORO) and laser
//! logs (CARMEN), and the Kümmerle et al. relations used to score maps. The only crate that
//! reads these files; the algorithms in `slam` stay free of I/O.

pub mod carmen;
pub mod posegraph;
pub mod relations;
