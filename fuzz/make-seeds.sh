#!/usr/bin/env bash
# Writes the seed inputs of the fuzz targets into DIR/<target>/ (README.md, "Corpora"): small
# excerpts of the public test data (tests/README.md; $LEVELMAP_DATA, else ../shared/data
# beside the repository), the node target's messages (examples/node_seeds.rs), the ROS 2
# samples (examples/ros2_cdr_seeds.rs), tiny Ouster captures (examples/pcap_ouster_seeds.rs),
# map version files (examples/map_version_seeds.rs) and localize requests and localizations
# (examples/localize_seeds.rs). The files
# read are never changed. The committed corpora are these seeds plus what the fuzzer found,
# minimized (`cargo fuzz cmin`).
set -euo pipefail
out="${1:?usage: fuzz/make-seeds.sh DIR}"
cd "$(dirname "$0")/.."
data="${LEVELMAP_DATA:-../shared/data}"
if [ ! -d "$data" ]; then
  echo "fuzz/make-seeds.sh: $data is missing (scripts/test-data.sh fetch)" >&2
  exit 1
fi
mkdir -p "$out"/{node,g2o,toro,carmen,relations,kitti,threedtk,ros2_cdr,pcap_ouster,map_version,localize}

# A pose graph's first N vertices and the edges among them (the whole graph is megabytes).
graph_excerpt() { # file vertex-tag edge-tag n
  awk -v vt="$2" -v et="$3" -v n="$4" \
    '$1 == vt && $2 < n { print } $1 == et && $2 < n && $3 < n { print }' "$1"
}
graph_excerpt "$data/pose_graph_2d/se-sync/intel.g2o" VERTEX_SE2 EDGE_SE2 20 > "$out/g2o/intel-20"
graph_excerpt "$data/pose_graph_2d/se-sync/city10000.g2o" VERTEX_SE2 EDGE_SE2 20 > "$out/g2o/city10000-20"
graph_excerpt "$data/pose_graph_2d/carlone/input_M3500b_g2o.g2o" VERTEX_SE2 EDGE_SE2 20 > "$out/g2o/m3500b-20"
# Edges only, full information matrices.
head -n 40 "$data/pose_graph_2d/se-sync/manhattan.g2o" > "$out/g2o/manhattan-40"
graph_excerpt "$data/pose_graph_2d/toro/CSAIL_P_toro.graph" VERTEX2 EDGE2 20 > "$out/toro/csail-20"
graph_excerpt "$data/pose_graph_2d/toro/FR079_P_toro.graph" VERTEX2 EDGE2 20 > "$out/toro/fr079-20"

# CARMEN: the header, PARAM, ODOM and FLASER lines of a raw log; ROBOTLASER1 lines; a
# corrected log. About 1-3 kB a scan line. The decompressor's SIGPIPE, once the excerpt is
# taken, is expected: the pipeline's status is the excerpt's (an empty one fails below).
(
  set +o pipefail
  bzcat "$data/radish_2d_laser_logs/aces.clf.bz2" | head -n 24 > "$out/carmen/aces-24"
  bzcat "$data/radish_2d_laser_logs/fr-clinic_robotlaser.clf.bz2" \
    | awk '$1 == "ROBOTLASER1" && ++n > 2 { exit } { print }' > "$out/carmen/fr-clinic-robotlaser"
  # Its first 200 ODOM lines precede the first scan: only the three after each scan are kept.
  zcat "$data/radish_2d_corrected_logs/intel-corrected.log.gz" \
    | awk '$1 == "FLASER" { f = 3 } $1 != "ODOM" || f-- > 0 { print } $1 == "NEFF" && ++n >= 2 { exit }' \
    > "$out/carmen/intel-corrected"
)
head -n 20 "$data/radish_2d_laser_logs/aces.relations" > "$out/relations/aces-20"

# KITTI: 256 consecutive points (one ring's arc), and every 512th point of a scan (all
# rings, all around).
head -c $((256 * 16)) "$data/kitti_velodyne/patchwork-plusplus/000000.bin" > "$out/kitti/000000-first-256"
python3 - "$data/kitti_velodyne/segregator/000020.bin" "$out/kitti/000020-every-512th" <<'EOF'
import sys
data = open(sys.argv[1], "rb").read()
open(sys.argv[2], "wb").write(b"".join(data[i:i + 16] for i in range(0, len(data), 512 * 16)))
EOF

# 3DTK: one nodding line (360 points) of a scan, then NUL and its .pose (the target's input
# layout); a middle line without a pose.
threedtk="$data/rotating_2d_laser_3d_scans_3dtk"
for scan in scan000 scan001; do
  { head -n 360 "$threedtk/$scan.3d"; printf '\0'; cat "$threedtk/$scan.pose"; } > "$out/threedtk/$scan-line-0"
done
sed -n "$((360 * 60 + 1)),$((360 * 61))p" "$threedtk/scan002.3d" > "$out/threedtk/scan002-line-60"

# Ouster: the shared capture's first two lidar packets and a cut third (records of 8490
# bytes from byte 24), and its global header with its first IMU datagram (the record at byte
# 34048, 106 bytes).
ouster="$data/ouster_organized_scans/OS-1-128_v2.3.0_1024x10_lb_n3.pcap"
head -c 20000 "$ouster" > "$out/pcap_ouster/os1-128-lb-cut"
{ head -c 24 "$ouster"; dd if="$ouster" iflag=skip_bytes,count_bytes skip=34048 count=106 status=none; } > "$out/pcap_ouster/os1-128-imu"

cargo run --quiet --locked --manifest-path fuzz/Cargo.toml --example node_seeds -- "$out/node"
cargo run --quiet --locked --manifest-path fuzz/Cargo.toml --example ros2_cdr_seeds -- "$out/ros2_cdr"
cargo run --quiet --locked --manifest-path fuzz/Cargo.toml --example pcap_ouster_seeds -- "$out/pcap_ouster"
cargo run --quiet --locked --manifest-path fuzz/Cargo.toml --example map_version_seeds -- "$out/map_version"
cargo run --quiet --locked --manifest-path fuzz/Cargo.toml --example localize_seeds -- "$out/localize"
if find "$out" -type f -empty | grep .; then
  echo "fuzz/make-seeds.sh: the seeds above are empty" >&2
  exit 1
fi
du -sh "$out"/*
