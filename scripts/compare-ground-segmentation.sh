#!/usr/bin/env bash
# Side by side, in one run: levelmap's segmentation + projection and Patchwork++ (the ground
# segmenter users pick today, peers/ground_seg_patchwork.py) on the four labelled KITTI frames.
# Prints one JSON line per frame and tool. Needs ../shared beside the repo.
#   scripts/compare-ground-segmentation.sh [VENV_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
SHARED=${LEVELMAP_SHARED:-../shared}
VENV=${1:-${HOME}/.cache/levelmap-peers-venv}
D=$SHARED/data/kitti_velodyne
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
  # Only what ground_seg_patchwork.py imports, at the versions of peers/requirements.txt.
  "$VENV/bin/pip" install -q "$(grep '^pypatchworkpp==' "$SHARED/peers/requirements.txt")" \
    "$(grep '^numpy==' "$SHARED/peers/requirements.txt")"
fi
cargo build -q --release -p levelmap
BIN=${CARGO_TARGET_DIR:-target}/release/levelmap
for frame in segregator/000020 segregator/000030 segregator/004413 patchwork-plusplus/000000; do
  labels=$D/segregator/$(basename "$frame").pred.label
  "$BIN" level "$D/$frame.bin" --labels "$labels" --repeat 20 --json |
    python3 -c 'import json,sys; r=json.load(sys.stdin); print(json.dumps({"tool":"levelmap","frame":sys.argv[1],"median_ms":r["elapsed_ms"],"landmark_precision":r["landmark_precision"],"beam_precision":r["beam_precision"],"points":r["points"]}))' "$frame"
  "$VENV/bin/python" "$SHARED/peers/ground_seg_patchwork.py" "$D/$frame.bin" --labels "$labels" --runs 20 |
    python3 -c 'import json,sys; r=json.loads(sys.stdin.readline()); print(json.dumps({"tool":"patchwork++","frame":sys.argv[1],"median_ms":r["median_s"]*1e3,"ground_precision":r.get("precision"),"points":r["n_points"]}))' "$frame"
done
