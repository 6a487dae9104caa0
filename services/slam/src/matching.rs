//! IDC scan matching (Lu & Milios) of 2D scans: relative pose, covariance, quality.
