//! levelmap simulator scans (JSON, written by `levelmap simulate`).
