#!/usr/bin/env bash
# Writes a mapper store with a given levelmap binary, for the upgrade tests
# (services/mapper/tests/fixtures/README.md): three robots map the park (coverage on, so a
# robot passes over another's ground; robot1's nodes carry their 3D clouds), the map is
# frozen as version 1, robot4 localizes on it without GPS (localized spans), and the mapper
# stops gracefully (a snapshot). What the mapper served then (robots, chains, modes,
# versions, summary) is written beside the store as expected.json, so a test compares the
# store opened by a later release with what the release that wrote it saw.
#
#   scripts/make-store-fixture.sh LEVELMAP_BINARY OUT_DIR RELEASE
#
# RELEASE names the source of the binary (e.g. "main 67c63cc"); it goes into expected.json.
# The binary is a build of the release whose store format the fixture records (the
# previous release's main), built with its default features (the lab: `levelmap edge`
# with the simulated source).
set -euo pipefail
bin="$(realpath "$1")" out="$2" release="${3:?name the release that built the binary}"
work="$(mktemp -d)"
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$work"' EXIT
http="127.0.0.1:18531" zenoh="tcp/127.0.0.1:18532" token="fixture"
api="http://$http/api/v1/fleets/park"

cat >"$work/mapper.toml" <<EOF
http_listen = "$http"
store_path = "$work/mapper.redb"
fleets = ["park"]
token = "$token"
[store]
snapshot_every_nodes = 40
[zenoh]
mode = "router"
listen = ["$zenoh"]
EOF
"$bin" mapper --config "$work/mapper.toml" 2>"$work/mapper.log" &
mapper=$!
for _ in $(seq 100); do curl -sf "http://$http/healthz" >/dev/null && break; sleep 0.2; done

# robot N: edge ROBOT LOOP DURATION GPS CLOUD
edge() {
  cat >"$work/$1.toml" <<EOF
fleet = "park"
robot = "$1"
outbox_path = "$work/$1-outbox.redb"
speed = 0
resend_after_ms = 500
[zenoh]
connect = ["$zenoh"]
[cloud]
keep = $5
max_points = 300
[source.sim]
loop_index = $2
seed = 7
duration_s = $3
gps = $4
EOF
  "$bin" edge --json --config "$work/$1.toml" >"$work/$1.json" 2>"$work/$1.log"
}
edge robot1 0 240 true true &
edge robot2 1 240 true false &
edge robot3 2 240 true false &
wait %2 %3 %4

auth=(-H "Authorization: Bearer $token")
curl -sf "${auth[@]}" -X POST "$api/versions" >/dev/null
curl -sf "${auth[@]}" -X PUT -H 'Content-Type: application/json' \
  -d '{"mode":"localize","version":1,"robots":["robot4"]}' "$api/modes" >/dev/null
edge robot4 0 20 false false

mkdir -p "$out"
get() { curl -sf "$api/$1" >"$work/$2.json"; }
get summary summary && get robots robots && get modes modes && get versions versions
get graph graph && get robots/robot4/localization localizations
curl -sf "http://$http/metrics" >"$work/metrics.txt"
# Python's json keeps 64-bit integers (times in ns) exact; jq would round them to doubles.
python3 - "$work" "$release" >"$out/expected.json" <<'PY'
import json, sys
work, release = sys.argv[1], sys.argv[2]
read = lambda name: json.load(open(f"{work}/{name}.json"))
passed = next(int(float(l.split()[1])) for l in open(f"{work}/metrics.txt")
              if l.startswith("levelmap_nodes_passed_total"))
print(json.dumps({
    "written_by": release,
    "summary": read("summary"), "robots": read("robots"), "modes": read("modes"),
    "versions": read("versions"), "localizations": len(read("localizations")),
    "nodes_passed": passed,
    "nodes": [{"robot": n["robot"], "node_seq": n["node_seq"]} for n in read("graph")["nodes"]],
}, indent=1))
PY
kill -TERM "$mapper"
wait "$mapper"
cp "$work/mapper.redb" "$out/mapper.redb"
ls -l "$out"
