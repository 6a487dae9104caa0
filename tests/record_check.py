"""Reads a `levelmap record` file with the reference MCAP reader (PyPI `mcap`) and decodes
every message with the protobuf schema embedded in the file (`mcap-protobuf-support`), as
Foxglove does. Prints one JSON object: messages per topic, each topic's schema, the distinct
nodes per robot (by chain and node_seq: re-sends count once), and the summary's figures.
With `levelmap record --foxglove`, also the messages in Foxglove's schemas: per kind, the
scans' returns and the frames /tf links. Fails on a message that does not decode or whose
header disagrees with its key."""

import math

import json
import sys

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory


def main(path):
    topics, schemas, nodes = {}, {}, {}
    beams = 0
    foxglove = {"returns": 0, "cloud_points": 0, "frames": set()}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, proto in reader.iter_decoded_messages():
            topics[channel.topic] = topics.get(channel.topic, 0) + 1
            schemas[channel.topic] = schema.name
            assert proto.DESCRIPTOR.full_name == schema.name, (channel.topic, schema.name)
            if schema.name == "levelmap.v1.Node":
                fleet, robot = channel.topic.split("/")[1], channel.topic.split("/")[3]
                header = proto.header
                assert (header.fleet_id, header.robot_id) == (fleet, robot), channel.topic
                assert message.publish_time == header.stamp_ns, channel.topic
                assert len(proto.scan.range_m) > 0, "a node without its scan"
                beams += len(proto.scan.range_m)
                nodes.setdefault(robot, set()).add((proto.chain_id, proto.node_seq))
            elif schema.name == "foxglove.LaserScan":
                robot = channel.topic.split("/")[3]
                assert proto.frame_id == f"park/{robot}/odom", (channel.topic, proto.frame_id)
                foxglove["returns"] += sum(1 for r in proto.ranges if not math.isnan(r))
            elif schema.name == "foxglove.PointCloud":
                assert proto.point_stride == 13 and len(proto.data) % 13 == 0, channel.topic
                foxglove["cloud_points"] += len(proto.data) // 13
            elif schema.name == "foxglove.LocationFix":
                assert -90 <= proto.latitude <= 90 and proto.latitude != 0, channel.topic
            elif schema.name == "foxglove.FrameTransforms":
                for t in proto.transforms:
                    foxglove["frames"].add(f"{t.parent_frame_id}>{t.child_frame_id}")
        summary = reader.get_summary()
    print(
        json.dumps(
            {
                "messages": sum(topics.values()),
                "topics": topics,
                "schemas": schemas,
                "nodes_per_robot": {r: len(n) for r, n in sorted(nodes.items())},
                "beams": beams,
                "summary_messages": summary.statistics.message_count,
                "chunk_indexes": len(summary.chunk_indexes),
                "foxglove": {**foxglove, "frames": sorted(foxglove["frames"])},
            }
        )
    )


if __name__ == "__main__":
    main(sys.argv[1])
