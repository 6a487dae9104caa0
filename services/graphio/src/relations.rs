//! Kümmerle et al. relations files.
