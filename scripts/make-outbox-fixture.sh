#!/usr/bin/env bash
# Writes a robot's outbox with a given levelmap binary, for the outbox upgrade test
# (services/edge/tests/fixtures/): a simulated robot (robot7 of park) drives 15 s of the park
# at 20x with no mapper to reach, so every node it makes stays in its outbox unacked. The
# outbox is gzipped into OUT_DIR beside expected.json, the edge's own report (`--json`) and
# the release that wrote it.
#
#   scripts/make-outbox-fixture.sh LEVELMAP_BINARY OUT_DIR RELEASE
#
# The binary is a build of the release whose outbox format the fixture records, with its
# default features (the simulated source).
set -euo pipefail
bin="$(realpath "$1")" out="$2" release="${3:?name the release that built the binary}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
mkdir -p "$out"
# Port 1: nothing answers, so nothing is acked.
LEVELMAP_OUTBOX_PATH="$work/outbox.redb" LEVELMAP_ROBOT=robot7 LEVELMAP_SPEED=20 \
  LEVELMAP_SOURCE__SIM__DURATION_S=15 LEVELMAP_LINGER_FOR_ACKS=false \
  LEVELMAP_ZENOH__CONNECT='["tcp/127.0.0.1:1"]' \
  "$bin" edge --json >"$work/report.json" 2>"$work/edge.log"
python3 - "$work/report.json" "$release" >"$out/expected.json" <<'PY'
import json, sys
report = json.load(open(sys.argv[1]))
json.dump({"release": sys.argv[2], "fleet": "park", "robot": report["robot"],
           "nodes": report["nodes"], "outbox_pending": report["outbox_pending"]},
          sys.stdout, indent=2)
print()
PY
gzip -9 -c "$work/outbox.redb" >"$out/outbox.redb.gz"
echo "$out: $(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["outbox_pending"])' "$out/expected.json") nodes pending"
