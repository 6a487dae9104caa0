"""A small ROS 2 recording written by rosbags (PyPI), for the edge's MCAP source test.

    python rosbags_recording.py DIR   # DIR/rec: a rosbag2 folder, MCAP storage

A robot drives 1 m/s along x for 3 s, rolled 0.05 rad (the IMU says so; odometry is flat),
beside a wall 4 m to its left: /odom at 20 Hz, /imu at 50 Hz, /fix at 1 Hz (the one at
t = 2 s without a fix), /points at 2 Hz (the wall, per-point time `t` in ns over 0.1 s), and
/tf_static (the lidar 0.2 m ahead and 1 m up, the antenna 0.3 m behind). The cloud at
t = 1 s is cut short: bad bytes for the source to refuse.
"""

import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

ts = get_typestore(Stores.ROS2_HUMBLE)
T = ts.types
T0 = 1_700_000_000 * 10**9


def stamp(ns):
    return T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def header(ns, frame):
    return T["std_msgs/msg/Header"](stamp=stamp(ns), frame_id=frame)


def vec(x, y, z):
    return T["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)


def quat(x, y, z, w):
    return T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)


def main(out):
    path = out / "rec"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = {}
        for topic, typename in [("/tf_static", "tf2_msgs/msg/TFMessage"), ("/odom", "nav_msgs/msg/Odometry"),
                                ("/imu", "sensor_msgs/msg/Imu"), ("/fix", "sensor_msgs/msg/NavSatFix"),
                                ("/points", "sensor_msgs/msg/PointCloud2")]:
            conn[topic] = w.add_connection(topic, typename, typestore=ts)
        events = []

        def put(ns, topic, msg):
            events.append((ns, topic, bytes(ts.serialize_cdr(msg, conn[topic].msgtype))))

        tf = lambda child, x, z: T["geometry_msgs/msg/TransformStamped"](
            header=header(T0, "base_link"), child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](translation=vec(x, 0.0, z), rotation=quat(0.0, 0.0, 0.0, 1.0)))
        put(T0, "/tf_static", T["tf2_msgs/msg/TFMessage"](transforms=[tf("lidar", 0.2, 1.0), tf("gps", -0.3, 0.5)]))
        cov9 = np.zeros(9)
        cov36 = np.zeros(36)
        for k in range(61):
            ns = T0 + k * 50_000_000
            pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=k * 0.05, y=0.0, z=0.0),
                                               orientation=quat(0.0, 0.0, 0.0, 1.0))
            put(ns, "/odom", T["nav_msgs/msg/Odometry"](
                header=header(ns, "odom"), child_frame_id="base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov36),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](linear=vec(1.0, 0, 0), angular=vec(0, 0, 0)), covariance=cov36)))
        roll = 0.05
        for k in range(151):
            ns = T0 + k * 20_000_000
            put(ns, "/imu", T["sensor_msgs/msg/Imu"](
                header=header(ns, "base_link"), orientation=quat(np.sin(roll / 2), 0.0, 0.0, np.cos(roll / 2)),
                orientation_covariance=cov9, angular_velocity=vec(0, 0, 0), angular_velocity_covariance=cov9,
                linear_acceleration=vec(0, 0, 9.81), linear_acceleration_covariance=cov9))
        for k in range(4):
            ns = T0 + k * 10**9
            status = -1 if k == 2 else 2
            put(ns, "/fix", T["sensor_msgs/msg/NavSatFix"](
                header=header(ns, "gps"), status=T["sensor_msgs/msg/NavSatStatus"](status=status, service=1),
                latitude=48.0 + k * 1e-5, longitude=7.8, altitude=280.0,
                position_covariance=np.diag([0.04, 0.04, 0.09]).ravel(), position_covariance_type=2))
        field = lambda name, offset, datatype: T["sensor_msgs/msg/PointField"](name=name, offset=offset, datatype=datatype, count=1)
        for k in range(6):
            ns = T0 + k * 500_000_000
            n = 400
            pts = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("t", "<u4")])
            pts["x"] = np.linspace(-8.0, 8.0, n)
            pts["y"] = 4.0
            pts["z"] = np.tile([-0.5, 0.0, 0.5, 1.0], n // 4)
            pts["t"] = np.arange(n) * 250_000
            msg = T["sensor_msgs/msg/PointCloud2"](
                header=header(ns, "lidar"), height=1, width=n,
                fields=[field("x", 0, 7), field("y", 4, 7), field("z", 8, 7), field("t", 12, 6)],
                is_bigendian=False, point_step=16, row_step=16 * n,
                data=np.frombuffer(pts.tobytes(), dtype=np.uint8), is_dense=True)
            put(ns, "/points", msg)
            if k == 2:
                ts_, topic, raw = events[-1]
                events[-1] = (ts_, topic, raw[: len(raw) // 2])
        for ns, topic, raw in sorted(events, key=lambda e: e[0]):
            w.write(conn[topic], ns, raw)


if __name__ == "__main__":
    main(Path(sys.argv[1]))
