"""The simulator's run, exported by fleetlab's tests/mcap_sim.rs, written as a ROS 2
recording by rosbags (PyPI; its own MCAP and CDR code, none of levelmap's):

    python sim_recording.py DIR   # DIR/{odom.bin, clouds.bin, clouds.json, fixes.json,
                                  #      tf.json} -> DIR/rec (rosbag2, MCAP storage)

/points: unorganized PointCloud2 (x, y, z float32, t uint32 ns after the stamp), published
at the sweep's end; /odom: nav_msgs/Odometry; /imu: the same attitude as sensor_msgs/Imu;
/fix: NavSatFix with the receiver's sigmas; /tf_static: the lidar and the antenna.
"""

import json
import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

ts = get_typestore(Stores.ROS2_HUMBLE)
T = ts.types


def stamp(ns):
    return T["builtin_interfaces/msg/Time"](sec=int(ns) // 10**9, nanosec=int(ns) % 10**9)


def header(ns, frame):
    return T["std_msgs/msg/Header"](stamp=stamp(ns), frame_id=frame)


def vec(v):
    return T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def quat(q):
    return T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))


def main(d):
    events = []
    cov9, cov36 = np.zeros(9), np.zeros(36)
    odom = np.fromfile(d / "odom.bin", dtype=[("stamp", "<u8"), ("pose", "<f8", 7)])
    for o in odom:
        ns, p = int(o["stamp"]), o["pose"]
        pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]), orientation=quat(p[3:]))
        events.append((ns, "/odom", T["nav_msgs/msg/Odometry"](
            header=header(ns, "odom"), child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov36),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=vec([0, 0, 0]), angular=vec([0, 0, 0])), covariance=cov36))))
        events.append((ns, "/imu", T["sensor_msgs/msg/Imu"](
            header=header(ns, "base_link"), orientation=quat(p[3:]), orientation_covariance=cov9,
            angular_velocity=vec([0, 0, 0]), angular_velocity_covariance=cov9,
            linear_acceleration=vec([0, 0, 9.81]), linear_acceleration_covariance=cov9)))
    points = np.fromfile(d / "clouds.bin", dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("t", "<u4")])
    field = lambda name, offset, datatype: T["sensor_msgs/msg/PointField"](name=name, offset=offset, datatype=datatype, count=1)
    fields = [field("x", 0, 7), field("y", 4, 7), field("z", 8, 7), field("t", 12, 6)]
    for c in json.loads((d / "clouds.json").read_text()):
        pts = points[c["first"]:c["first"] + c["count"]]
        msg = T["sensor_msgs/msg/PointCloud2"](
            header=header(c["stamp"], "lidar"), height=1, width=len(pts), fields=fields,
            is_bigendian=False, point_step=16, row_step=16 * len(pts),
            data=np.frombuffer(pts.tobytes(), dtype=np.uint8), is_dense=False)
        events.append((c["stamp"] + int(pts["t"].max()), "/points", msg))
    for f in json.loads((d / "fixes.json").read_text()):
        cov = np.diag([f["sigma_h"] ** 2, f["sigma_h"] ** 2, f["sigma_v"] ** 2]).ravel()
        events.append((f["stamp"], "/fix", T["sensor_msgs/msg/NavSatFix"](
            header=header(f["stamp"], "gps"), status=T["sensor_msgs/msg/NavSatStatus"](status=2, service=1),
            latitude=f["lat"], longitude=f["lon"], altitude=f["alt"],
            position_covariance=cov, position_covariance_type=2)))
    tf = json.loads((d / "tf.json").read_text())
    first = min(e[0] for e in events)

    def transform(child, t, q):
        return T["geometry_msgs/msg/TransformStamped"](
            header=header(first, "base_link"), child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](translation=vec(t), rotation=quat(q)))

    events.append((first, "/tf_static", T["tf2_msgs/msg/TFMessage"](transforms=[
        transform("lidar", tf["lidar"][:3], tf["lidar"][3:]), transform("gps", tf["gps"], [0, 0, 0, 1])])))
    types = {"/points": "sensor_msgs/msg/PointCloud2", "/odom": "nav_msgs/msg/Odometry", "/imu": "sensor_msgs/msg/Imu",
             "/fix": "sensor_msgs/msg/NavSatFix", "/tf_static": "tf2_msgs/msg/TFMessage"}
    with Writer(d / "rec", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = {topic: w.add_connection(topic, typename, typestore=ts) for topic, typename in types.items()}
        for ns, topic, msg in sorted(events, key=lambda e: (e[0], e[1] != "/tf_static")):
            w.write(conn[topic], ns, bytes(ts.serialize_cdr(msg, types[topic])))


if __name__ == "__main__":
    main(Path(sys.argv[1]))
