"""A Foxglove client written from the published WebSocket protocol (foxglove.sdk.v1, as the
foxglove SDK 0.26 serves it; the JSON ops of foxglove.websocket.v1), decoding with PyPI's
foxglove-schemas-protobuf and checking against the mapper's HTTP API. Two modes:

    python foxglove_check.py map WS_URL HTTP_BASE FLEET ROBOT TOKEN
    python foxglove_check.py live WS_URL HTTP_BASE FLEET ROBOT TOKEN COUNT

`map`: the fleet's grid and the robot's pose (map.json, map.yaml?mode=scale, map.pgm, the
robot's pose). `live`, started before the robot drives: first that a connection without the
token (WS_URL without its query) is refused with 401; then the robot's first COUNT leveled
scans, clouds and GPS fixes, each against its node (GET …/nodes/{id}, …/nodes/{id}/cloud,
the fleet's datum). TOKEN is the mapper's read token ("" for none), for the HTTP API too.

Prints a JSON report; exits 1 naming the first difference.
"""

import asyncio
import json
import math
import struct
import sys
import urllib.request

import websockets
from foxglove_schemas_protobuf.Grid_pb2 import Grid
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan
from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame

TOKEN = ""


def fail(why):
    print(json.dumps({"error": why}))
    print(why, file=sys.stderr)
    sys.exit(1)


def http(base, path):
    request = urllib.request.Request(base + path)
    if TOKEN:
        request.add_header("Authorization", f"Bearer {TOKEN}")
    with urllib.request.urlopen(request, timeout=30) as r:
        return r.read()


async def receive(ws_url, topics, timeout_s=60, count=1):
    """The first `count` messages on each of `topics`: {topic: [(schema name, encoding,
    payload)]}."""
    got, advertised, subscribed = {}, {}, {}
    async with websockets.connect(ws_url, subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:
        deadline = asyncio.get_running_loop().time() + timeout_s
        while len(got) < len(topics) or any(len(m) < count for m in got.values()):
            left = deadline - asyncio.get_running_loop().time()
            if left <= 0:
                fail(f"no message within {timeout_s} s on {sorted(set(topics) - set(got))}; "
                     f"advertised {sorted(c['topic'] for c in advertised.values())}")
            frame = await asyncio.wait_for(ws.recv(), left)
            if isinstance(frame, str):
                op = json.loads(frame)
                if op.get("op") == "advertise":
                    for channel in op["channels"]:
                        advertised[channel["id"]] = channel
                        if channel["topic"] in topics and channel["topic"] not in subscribed.values():
                            sub = len(subscribed) + 1
                            subscribed[sub] = channel["topic"]
                            await ws.send(json.dumps({
                                "op": "subscribe",
                                "subscriptions": [{"id": sub, "channelId": channel["id"]}],
                            }))
                continue
            # Binary: opcode 1 (message data), subscription id u32 LE, log time u64 LE, data.
            if frame[0] != 1:
                continue
            sub, _log_time = struct.unpack_from("<IQ", frame, 1)
            topic = subscribed.get(sub)
            if topic and len(got.get(topic, [])) < count:
                channel = next(c for c in advertised.values() if c["topic"] == topic)
                got.setdefault(topic, []).append(
                    (channel["schemaName"], channel["encoding"], frame[13:]))
    return got


def yaw(q):
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def check_map(ws_url, base, fleet, robot):
    grid_topic, pose_topic = f"/{fleet}/grid", f"/{fleet}/robots/{robot}/pose"
    got = asyncio.run(receive(ws_url, [grid_topic, pose_topic]))

    schema, encoding, payload = got[grid_topic][0]
    if (schema, encoding) != ("foxglove.Grid", "protobuf"):
        fail(f"{grid_topic}: {schema} in {encoding}")
    grid = Grid()
    grid.ParseFromString(payload)
    rows = len(grid.data) // grid.row_stride
    placement = json.loads(http(base, f"/api/v1/fleets/{fleet}/map.json"))
    origin = (grid.pose.position.x, grid.pose.position.y)
    if (grid.column_count, rows) != (placement["width"], placement["height"]):
        fail(f"grid {grid.column_count}x{rows}, HTTP {placement}")
    if grid.cell_size.x != placement["resolution_m"] or list(origin) != placement["origin_m"]:
        fail(f"grid cell {grid.cell_size.x} at {origin}, HTTP {placement}")
    fields = [(f.name, f.offset) for f in grid.fields]
    if grid.frame_id != f"{fleet}/map" or fields != [("occupancy", 0), ("state", 1)]:
        fail(f"grid frame {grid.frame_id}, fields {fields}")
    if grid.cell_stride != 2 or grid.row_stride != 2 * grid.column_count:
        fail(f"grid strides {grid.cell_stride}, {grid.row_stride}")

    # The cells, classified with the grid's own thresholds, and their `state`, against map.pgm
    # (top row first).
    yaml = http(base, f"/api/v1/fleets/{fleet}/map.yaml?mode=scale").decode()
    thresh = {k.strip(): float(v) for k, v in
              (line.split(":", 1) for line in yaml.splitlines() if "_thresh" in line)}
    occupied, free = round(thresh["occupied_thresh"] * 100), round(thresh["free_thresh"] * 100)
    pgm = http(base, f"/api/v1/fleets/{fleet}/map.pgm")
    width = grid.column_count
    pixels = pgm[-width * rows:]
    counts = {"unknown": 0, "free": 0, "occupied": 0}
    data = grid.data  # once: each read of a bytes field is a copy
    for row in range(rows):
        for col in range(width):
            at = row * grid.row_stride + col * grid.cell_stride
            c = data[at] - 256 if data[at] > 127 else data[at]
            state = ("unknown" if c < 0 else "occupied" if c >= occupied
                     else "free" if c <= free else "unknown")
            counts[state] += 1
            want = {"unknown": 205, "free": 254, "occupied": 0}[state]
            have = pixels[(rows - 1 - row) * width + col]
            if have != want:
                fail(f"cell ({col}, {row}): {c} % is {state}, map.pgm has {have}")
            shade = {"free": 0, "unknown": 1, "occupied": 2}[state]
            if data[at + 1] != shade:
                fail(f"cell ({col}, {row}): state {data[at + 1]}, map.pgm says {state}")

    schema, encoding, payload = got[pose_topic][0]
    if (schema, encoding) != ("foxglove.PoseInFrame", "protobuf"):
        fail(f"{pose_topic}: {schema} in {encoding}")
    pose = PoseInFrame()
    pose.ParseFromString(payload)
    state = json.loads(http(base, f"/api/v1/fleets/{fleet}/robots/{robot}/pose"))
    want = state["pose"]
    have = {"x": pose.pose.position.x, "y": pose.pose.position.y,
            "theta": yaw(pose.pose.orientation)}
    dtheta = math.remainder(have["theta"] - want["theta"], math.tau)
    if abs(have["x"] - want["x"]) > 1e-9 or abs(have["y"] - want["y"]) > 1e-9 or abs(dtheta) > 1e-9:
        fail(f"pose {have}, HTTP {want}")
    print(json.dumps({
        "grid": {"width": width, "height": rows, "resolution_m": grid.cell_size.x,
                 "origin_m": origin, "cells": counts, "frame_id": grid.frame_id},
        "pose": {"frame_id": pose.frame_id, **have},
        "http_pose": want,
    }))


def decoded(got, topic, schema_name, message):
    out = []
    for schema, encoding, payload in got[topic]:
        if (schema, encoding) != (schema_name, "protobuf"):
            fail(f"{topic}: {schema} in {encoding}")
        m = message()
        m.ParseFromString(payload)
        out.append(m)
    return out


def stamp_ns(t):
    return t.seconds * 1_000_000_000 + t.nanos


def to_enu(datum, lat, lon, h):
    """WGS84 geodetic to east-north-up (m) about `datum` (degrees, m)."""
    a, f = 6378137.0, 1 / 298.257223563
    e2 = f * (2 - f)

    def ecef(lat, lon, h):
        lat, lon = math.radians(lat), math.radians(lon)
        n = a / math.sqrt(1 - e2 * math.sin(lat) ** 2)
        return ((n + h) * math.cos(lat) * math.cos(lon), (n + h) * math.cos(lat) * math.sin(lon),
                (n * (1 - e2) + h) * math.sin(lat))

    lat0, lon0 = math.radians(datum["latitude_deg"]), math.radians(datum["longitude_deg"])
    p = ecef(lat, lon, h)
    o = ecef(datum["latitude_deg"], datum["longitude_deg"], datum["height_m"])
    d = [p[i] - o[i] for i in range(3)]
    east = -math.sin(lon0) * d[0] + math.cos(lon0) * d[1]
    north = (-math.sin(lat0) * math.cos(lon0) * d[0] - math.sin(lat0) * math.sin(lon0) * d[1]
             + math.cos(lat0) * d[2])
    return east, north


def binned(bearings, ranges, n):
    """LaserScan's ranges of a leveled scan, from docs/foxglove.md: n bearings over the whole
    turn from -pi when the beams cover it but for two steps, else over their span; each
    return at its nearest bearing, the nearer of two; NaN without one."""
    wrapped = [(b + math.pi) % math.tau - math.pi for b in bearings]
    lo, hi = min(wrapped), max(wrapped)
    if hi - lo > math.tau * (1 - 2 / n):
        start, step, turn = -math.pi, math.tau / n, True
    else:
        start, step, turn = lo, (hi - lo) / (n - 1), False
    out = [math.nan] * n
    for b, r in zip(wrapped, ranges):
        if r <= 0:
            continue
        i = round((b - start) / step)
        i = i % n if turn else min(max(i, 0), n - 1)
        if not out[i] <= r:
            out[i] = r
    return start, step, out


def check_live(ws_url, base, fleet, robot, count):
    # Without the token: refused before the WebSocket opens.
    bare = ws_url.split("?", 1)[0]
    try:
        asyncio.run(receive(bare, ["/tf"], timeout_s=10))
        fail(f"{bare}: connected without the token")
    except websockets.exceptions.InvalidStatus as e:
        refused = e.response.status_code
        if refused != 401:
            fail(f"{bare}: answered {refused}, not 401")
    topics = {what: f"/{fleet}/robots/{robot}/{what}" for what in ("scan", "cloud", "gps")}
    got = asyncio.run(receive(ws_url, list(topics.values()), timeout_s=180, count=count))
    summary = json.loads(http(base, f"/api/v1/fleets/{fleet}/summary"))
    by_stamp = {}
    for i in range(summary["nodes"]):
        node = json.loads(http(base, f"/api/v1/fleets/{fleet}/nodes/{i}"))
        if node["robot"] == robot:
            by_stamp[node["stamp_ns"]] = node
    report = {"refused_without_token": refused, "scans": [], "clouds": [], "fixes": []}

    for scan in decoded(got, topics["scan"], "foxglove.LaserScan", LaserScan):
        node = by_stamp.get(stamp_ns(scan.timestamp))
        if node is None or scan.frame_id != f"{fleet}/map":
            fail(f"scan at {stamp_ns(scan.timestamp)} in {scan.frame_id}: no such node")
        n = len(scan.ranges)
        start, step, want = binned(node["scan"]["bearing_rad"], node["scan"]["range_m"], n)
        if abs(scan.start_angle - start) > 1e-6 or abs(scan.end_angle - (start + step * (n - 1))) > 1e-6:
            fail(f"node {node['id']}: angles {scan.start_angle}..{scan.end_angle}, want {start}, step {step}")
        # The ranges are f32s: HTTP prints them shortest, the scan carries them as f64s.
        f32 = lambda v: struct.unpack("<f", struct.pack("<f", v))[0]
        for i, (have, w) in enumerate(zip(scan.ranges, want)):
            if not (math.isnan(have) and math.isnan(w)) and f32(have) != f32(w):
                fail(f"node {node['id']}: range {i} is {have}, its beams give {w}")
        returns = sum(1 for r in scan.ranges if not math.isnan(r))
        report["scans"].append({"node": node["id"], "bins": n, "returns": returns})

    for cloud in decoded(got, topics["cloud"], "foxglove.PointCloud", PointCloud):
        node = by_stamp.get(stamp_ns(cloud.timestamp))
        if node is None:
            fail(f"cloud at {stamp_ns(cloud.timestamp)}: no such node")
        want = json.loads(http(base, f"/api/v1/fleets/{fleet}/nodes/{node['id']}/cloud"))
        names = [(f.name, f.offset) for f in cloud.fields]
        if names != [("x", 0), ("y", 4), ("z", 8), ("class", 12)] or cloud.point_stride != 13:
            fail(f"cloud fields {names}, stride {cloud.point_stride}")
        data = cloud.data
        points = len(data) // 13
        if points != len(want["classes"]) or points == 0:
            fail(f"node {node['id']}: {points} points, HTTP {len(want['classes'])}")
        for k in range(points):
            x, y, z, c = struct.unpack_from("<fffB", data, 13 * k)
            wx, wy, wz = want["points"][3 * k: 3 * k + 3]
            if max(abs(x - wx), abs(y - wy), abs(z - wz)) > 1e-5 or c != want["classes"][k]:
                fail(f"node {node['id']} point {k}: {(x, y, z, c)}, HTTP {(wx, wy, wz, want['classes'][k])}")
        report["clouds"].append({"node": node["id"], "points": points})

    datum = summary["datum"]
    if datum is None:
        fail("no datum: the fleet took no fix")
    for fix in decoded(got, topics["gps"], "foxglove.LocationFix", LocationFix):
        node = by_stamp.get(stamp_ns(fix.timestamp))
        if node is None:
            fail(f"fix at {stamp_ns(fix.timestamp)}: no such node")
        east, north = to_enu(datum, fix.latitude, fix.longitude, fix.altitude)
        near = min(math.dist((east, north), g["position_m"]) for g in node["gps"])
        if near > 1e-3:
            fail(f"node {node['id']}: fix at ({east}, {north}), {near} m from the node's fixes")
        report["fixes"].append({"node": node["id"], "off_m": near})
    print(json.dumps(report))


def main():
    global TOKEN
    mode, ws_url, base, fleet, robot, TOKEN = sys.argv[1:7]
    if mode == "map":
        check_map(ws_url, base, fleet, robot)
    elif mode == "live":
        check_live(ws_url, base, fleet, robot, int(sys.argv[7]))
    else:
        fail(f"mode {mode}: map or live")


main()
