#!/usr/bin/env bash
# Side by side, in one run: levelmap's optimizer and the peers users pick (GTSAM LM/GN, g2o
# LM/GN through peers/pose_graph_gtsam.py) on the same g2o files. One JSON line per tool, each
# the median of 5 runs in one process: levelmap's `total_ms` is the time to the optimum from
# the file's edges (the chordal initialization included); the peers' `solve_ms` is their
# optimize() from the file's vertices.
#   [PEERS=g2o_gn,...] scripts/compare-pose-graph.sh [VENV_DIR] [FILES...]
# PEERS picks the peers' solvers (default all four: gtsam_lm,gtsam_gn,g2o_lm,g2o_gn).
set -euo pipefail
cd "$(dirname "$0")/.."
SHARED=${LEVELMAP_SHARED:-../shared}
VENV=${1:-${HOME}/.cache/levelmap-peers-graph}
shift || true
FILES=("$@")
[ ${#FILES[@]} -gt 0 ] || FILES=("$SHARED/data/pose_graph_2d/se-sync/manhattan.g2o" "$SHARED/data/pose_graph_2d/se-sync/city10000.g2o")
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install -q $(grep -E '^(gtsam|g2opy|numpy)==' "$SHARED/peers/requirements.txt")
fi
cargo build -q --release -p levelmap
BIN=${CARGO_TARGET_DIR:-target}/release/levelmap
for f in "${FILES[@]}"; do
  "$BIN" optimize "$f" --json --repeat 5 | python3 -c 'import json,sys; r=json.load(sys.stdin); print(json.dumps({"tool":"levelmap","init":"chordal","file":r["file"],"final_chi2_g2o_conv":r["final_chi2"],"iterations":r["iterations"],"solve_ms":r["solve_ms"],"init_ms":r["init_ms"],"total_ms":r["total_ms"]}))'
  "$VENV/bin/python" "$SHARED/peers/pose_graph_gtsam.py" "$f" --solvers "${PEERS:-gtsam_lm,gtsam_gn,g2o_lm,g2o_gn}" --repeat 5 --out-dir "$(mktemp -d)" |
    python3 -c 'import json,sys
for line in sys.stdin:
    r=json.loads(line); print(json.dumps({"tool":r.get("tool"),"algorithm":r.get("algorithm"),"file":r.get("file"),"final_chi2_g2o_conv":r.get("final_chi2_g2o_conv"),"iterations":r.get("iterations"),"solve_ms":1e3*r.get("optimize_wall_s",float("nan"))}))'
done
