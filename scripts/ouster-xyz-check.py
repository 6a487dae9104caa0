#!/usr/bin/env python3
"""Compares scanio's Ouster XYZ with the Ouster SDK's (PyPI ouster-sdk, its XYZLut).

    ouster-xyz-check.py FILE.pcap FILE.json OURS.bin [MAX_MM]

OURS.bin comes from `cargo run -p scanio --example ouster_xyz -- FILE.pcap FILE.json OURS.bin`:
the first complete frame, staggered, float64 x y z (m) per pixel. Prints one JSON line and
exits 1 if any pixel differs by more than MAX_MM (default 1 mm) or the returns differ.
"""
import json
import sys

import numpy as np
import ouster.sdk as sdk
from ouster.sdk import core

pcap, meta, ours_path = sys.argv[1:4]
max_mm = float(sys.argv[4]) if len(sys.argv) > 4 else 1.0
source = sdk.open_source(pcap, meta=[meta])
scan = next(iter(source))[0]
lut = core.XYZLut(scan.sensor_info)
theirs = lut(scan.field(core.ChanField.RANGE)).reshape(-1, 3)
ours = np.fromfile(ours_path, dtype="<f8").reshape(-1, 3)
if ours.shape != theirs.shape:
    sys.exit(f"{ours_path}: {ours.shape} points, the SDK has {theirs.shape}")
returns = np.any(theirs != 0, axis=1)
same_returns = bool(np.array_equal(returns, np.any(ours != 0, axis=1)))
diff_mm = np.linalg.norm(ours - theirs, axis=1) * 1e3
report = {
    "pcap": pcap,
    "frame_id": int(scan.frame_id),
    "points": int(len(ours)),
    "returns": int(returns.sum()),
    "same_returns": same_returns,
    "max_diff_mm": float(diff_mm.max()),
    "mean_diff_mm": float(diff_mm[returns].mean()) if returns.any() else 0.0,
    "ouster_sdk": sdk.__version__,
}
print(json.dumps(report))
if not same_returns or report["max_diff_mm"] > max_mm or returns.sum() == 0:
    sys.exit(f"{pcap}: scanio's XYZ differs from the Ouster SDK's: {report}")
