"""A Foxglove client written from the published WebSocket protocol (foxglove.sdk.v1, as the
foxglove SDK 0.26 serves it; the JSON ops of foxglove.websocket.v1): subscribes to a fleet's
grid and a robot's pose, decodes them with PyPI's foxglove-schemas-protobuf, and checks them
against the mapper's HTTP API (map.json, map.yaml?mode=scale, map.pgm, the robot's pose).

    python foxglove_check.py WS_URL HTTP_BASE FLEET ROBOT

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
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame


def fail(why):
    print(json.dumps({"error": why}))
    print(why, file=sys.stderr)
    sys.exit(1)


def http(base, path):
    with urllib.request.urlopen(base + path, timeout=30) as r:
        return r.read()


async def receive(ws_url, topics, timeout_s=60):
    """The first message on each of `topics`: {topic: (schema name, encoding, payload)}."""
    got, advertised, subscribed = {}, {}, {}
    async with websockets.connect(ws_url, subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:
        deadline = asyncio.get_running_loop().time() + timeout_s
        while len(got) < len(topics):
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
            if topic and topic not in got:
                channel = next(c for c in advertised.values() if c["topic"] == topic)
                got[topic] = (channel["schemaName"], channel["encoding"], frame[13:])
    return got


def yaw(q):
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def main():
    ws_url, base, fleet, robot = sys.argv[1:5]
    grid_topic, pose_topic = f"/{fleet}/grid", f"/{fleet}/robots/{robot}/pose"
    got = asyncio.run(receive(ws_url, [grid_topic, pose_topic]))

    schema, encoding, payload = got[grid_topic]
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
    if grid.frame_id != f"{fleet}/map" or [f.name for f in grid.fields] != ["occupancy"]:
        fail(f"grid frame {grid.frame_id}, fields {[f.name for f in grid.fields]}")

    # The same grid's cells, classified with its own thresholds, against map.pgm (top row first).
    yaml = http(base, f"/api/v1/fleets/{fleet}/map.yaml?mode=scale").decode()
    thresh = {k.strip(): float(v) for k, v in
              (line.split(":", 1) for line in yaml.splitlines() if "_thresh" in line)}
    occupied, free = round(thresh["occupied_thresh"] * 100), round(thresh["free_thresh"] * 100)
    pgm = http(base, f"/api/v1/fleets/{fleet}/map.pgm")
    pixels = pgm[-len(grid.data):]
    width = grid.column_count
    cells = [c - 256 if c > 127 else c for c in grid.data]
    counts = {"unknown": 0, "free": 0, "occupied": 0}
    for row in range(rows):
        for col in range(width):
            c = cells[row * width + col]
            state = ("unknown" if c < 0 else "occupied" if c >= occupied
                     else "free" if c <= free else "unknown")
            counts[state] += 1
            want = {"unknown": 205, "free": 254, "occupied": 0}[state]
            have = pixels[(rows - 1 - row) * width + col]
            if have != want:
                fail(f"cell ({col}, {row}): {c} % is {state}, map.pgm has {have}")

    schema, encoding, payload = got[pose_topic]
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


main()
