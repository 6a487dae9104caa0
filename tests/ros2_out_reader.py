"""The ROS 2 side of tests/e2e_ros2_out.rs: what levelmap gives back to ROS 2, read with the
Python Zenoh (eclipse-zenoh) and decoded by rosbags' own CDR code (PyPI; none of levelmap's).

    python ros2_out_reader.py ENDPOINT DIR FLEET rmw_zenoh|ros2dds [NAMESPACE]

Connects to ENDPOINT as a client and subscribes to `/tf` and `/levelmap/FLEET/map`: as an
rmw_zenoh subscription would, on the keys made from rosbags' own type hashes (Jazzy), or as
zenoh-bridge-ros2dds lays them, on `[NAMESPACE/]topic`. Every
transform is kept with its rmw_zenoh attachment, and every liveliness token (rmw_zenoh's graph)
seen. When DIR/stop appears, it queries the map key (a late joiner) and writes
DIR/ros2_out.json.
"""

import json
import struct
import sys
import time
from pathlib import Path

import zenoh
from rosbags.typesys import Stores, get_typestore

ts = get_typestore(Stores.ROS2_JAZZY)


def dds_type(name):
    package, _, msg = name.rpartition("/")
    return f"{package.replace('/', '::')}::dds_::{msg}_"


def key(topic, msgtype, style, namespace):
    if style == "ros2dds":
        return f"{namespace}/{topic.lstrip('/')}" if namespace else topic.lstrip("/")
    return f"0/{topic.lstrip('/')}/{dds_type(msgtype)}/{ts.hash_rihs01(msgtype)}"


def grid(raw):
    g = ts.deserialize_cdr(raw, "nav_msgs/msg/OccupancyGrid")
    return {
        "frame_id": g.header.frame_id,
        "resolution": float(g.info.resolution),
        "width": int(g.info.width),
        "height": int(g.info.height),
        "origin": [float(g.info.origin.position.x), float(g.info.origin.position.y)],
        "data": [int(v) for v in g.data],
    }


def main(endpoint, out, fleet, style, namespace=""):
    out = Path(out)
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    transforms, grids, tokens = [], [], set()

    def on_tf(sample):
        tf = ts.deserialize_cdr(sample.payload.to_bytes(), "tf2_msgs/msg/TFMessage")
        attachment = sample.attachment.to_bytes() if sample.attachment is not None else b""
        seq, source_ns, gid = struct.unpack("<qq16s", attachment) if len(attachment) == 32 else (-1, -1, b"")
        for t in tf.transforms:
            q = t.transform.rotation
            transforms.append({
                "stamp_ns": t.header.stamp.sec * 1_000_000_000 + t.header.stamp.nanosec,
                "frame_id": t.header.frame_id,
                "child_frame_id": t.child_frame_id,
                "x": t.transform.translation.x,
                "y": t.transform.translation.y,
                "z": t.transform.translation.z,
                "quaternion": [q.x, q.y, q.z, q.w],
                "attachment_len": len(attachment),
                "sequence": seq,
                "source_ns": source_ns,
            })

    tf_key = key("/tf", "tf2_msgs/msg/TFMessage", style, namespace)
    map_key = key(f"/levelmap/{fleet}/map", "nav_msgs/msg/OccupancyGrid", style, namespace)
    with zenoh.open(config) as session:
        session.declare_subscriber(tf_key, on_tf)
        session.declare_subscriber(map_key, lambda s: grids.append(grid(s.payload.to_bytes())))
        session.liveliness().declare_subscriber("@ros2_lv/**", lambda s: tokens.add(str(s.key_expr)), history=True)
        (out / "ready").write_text("")
        deadline = time.time() + 300
        while not (out / "stop").exists():
            if time.time() > deadline:
                sys.exit("no stop file in 300 s")
            time.sleep(0.05)
        queried = [grid(r.ok.payload.to_bytes()) for r in session.get(map_key, timeout=10.0) if r.ok is not None]
        report = {
            "tf_key": tf_key,
            "map_key": map_key,
            "transforms": transforms,
            "grids_received": len(grids),
            "last_grid_received": grids[-1] if grids else None,
            "queried": queried,
            "tokens": sorted(tokens),
        }
        (out / "ros2_out.json").write_text(json.dumps(report))


if __name__ == "__main__":
    main(*sys.argv[1:])
