//! Writes the first complete frame of an Ouster capture as XYZ (m, float64 little-endian,
//! x y z per pixel, staggered row-major as the SDK's `XYZLut` gives them; 0 0 0 for no
//! return), for `scripts/ouster-xyz-check.py` to compare with the Ouster SDK.
//!
//!     cargo run -p scanio --example ouster_xyz -- FILE.pcap FILE.json OUT.bin

use scanio::ouster::{FrameReader, SensorMeta, XyzLut};
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    let [pcap, meta, out] = args.as_slice() else {
        return Err("usage: ouster_xyz FILE.pcap FILE.json OUT.bin".into());
    };
    let meta = SensorMeta::load(meta)?;
    let lut = XyzLut::new(&meta);
    let mut reader = FrameReader::open(pcap, meta.clone())?;
    let frame = reader
        .next_frame()
        .ok_or_else(|| format!("{}: no complete frame", pcap.display()))?;
    let w = meta.columns_per_frame;
    let mut bytes = Vec::with_capacity(frame.ranges_mm.len() * 24);
    for (i, &range) in frame.ranges_mm.iter().enumerate() {
        let (row, col) = (i / w, i % w);
        let xyz = if frame.column_valid[col] {
            lut.xyz_m(row, col, range).unwrap_or([0.0; 3])
        } else {
            [0.0; 3]
        };
        xyz.iter().for_each(|v| bytes.extend(v.to_le_bytes()));
    }
    std::fs::write(out, bytes)?;
    eprintln!(
        "{}: frame {} ({} × {}) written to {}",
        pcap.display(),
        frame.frame_id,
        meta.pixels_per_column,
        w,
        out.display()
    );
    Ok(())
}
