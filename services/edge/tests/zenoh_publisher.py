"""Puts a rosbag2 recording's messages live on rmw_zenoh keys with the Python Zenoh
(eclipse-zenoh, PyPI; none of levelmap's code), for the edge's `[source.ros2]` test:

    python zenoh_publisher.py ENDPOINT RECORDING rmw_zenoh|ros2dds

It listens on ENDPOINT (peer mode), waits until the levelmap source subscribes to the
cloud topic, then publishes every message in time order, one every 2 ms (blocking while the link is
congested), on
`0/<topic>/<dds type>/RIHS01_<hash>` as rmw_zenoh does, or on `<topic>` as
zenoh-bridge-ros2dds does.
"""

import sys
import time

import zenoh
from rosbags.rosbag2 import Reader


def dds_type(name):
    package, _, msg = name.rpartition("/")
    return f"{package.replace('/', '::')}::dds_::{msg}_"


def main(endpoint, recording, style):
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("listen/endpoints", f'["{endpoint}"]')
    config.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(config) as session, Reader(recording) as reader:
        publishers = {}
        for c in reader.connections:
            topic = c.topic.lstrip("/")
            key = f"0/{topic}/{dds_type(c.msgtype)}/RIHS01_{'0' * 64}" if style == "rmw_zenoh" else topic
            # Blocking, not dropping, when the link is congested: a loaded test machine must
            # not lose messages the test counts.
            publishers[c.topic] = session.declare_publisher(
                key, congestion_control=zenoh.CongestionControl.BLOCK
            )
        cloud = publishers["/points"]
        deadline = time.time() + 30
        while not cloud.matching_status.matching:
            if time.time() > deadline:
                sys.exit("no subscriber in 30 s")
            time.sleep(0.05)
        # Every subscription of the source, not just the first, must be in place.
        time.sleep(1.0)
        for connection, _, raw in reader.messages():
            publishers[connection.topic].put(bytes(raw))
            time.sleep(0.002)
        time.sleep(1.0)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3])
