"""The other side of ros2msg's cross-implementation test: rosbags (PyPI) encodes and
decodes the messages with its own CDR code.

    python rosbags_messages.py write DIR   # NAME.{le,be}.cdr + NAME.json (the message)
    python rosbags_messages.py read DIR    # NAME.rust.cdr -> NAME.rust.json
    python rosbags_messages.py hashes DIR  # hashes.json: each type's RIHS01 hash (Jazzy)
"""

import json
import sys
from pathlib import Path

import numpy as np
from rosbags.typesys import Stores, get_typestore

ts = get_typestore(Stores.ROS2_HUMBLE)
T = ts.types


def plain(value):
    """A rosbags message as JSON-ready dicts and lists."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if hasattr(value, "__dataclass_fields__"):
        return {k: plain(getattr(value, k)) for k in value.__dataclass_fields__ if k != "__msgtype__" and not k.isupper()}
    if isinstance(value, list):
        return [plain(v) for v in value]
    if isinstance(value, (np.integer, np.floating)):
        return value.item()
    return value


def header(sec, nanosec, frame):
    return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=frame)


def vec(x, y, z):
    return T["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)


def quat(x, y, z, w):
    return T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)


def messages():
    cov9 = np.arange(9, dtype=np.float64) * 0.5
    cov36 = np.arange(36, dtype=np.float64) * 0.25
    yield "navsatfix", "sensor_msgs/msg/NavSatFix", T["sensor_msgs/msg/NavSatFix"](
        header=header(1700000000, 123456789, "gps"),
        status=T["sensor_msgs/msg/NavSatStatus"](status=2, service=1),
        latitude=48.0123456789, longitude=7.8352, altitude=281.25,
        position_covariance=cov9, position_covariance_type=2)
    yield "imu", "sensor_msgs/msg/Imu", T["sensor_msgs/msg/Imu"](
        header=header(1700000001, 5, "imu_link"), orientation=quat(0.01, -0.02, 0.3, 0.953),
        orientation_covariance=cov9, angular_velocity=vec(0.1, -0.2, 0.3),
        angular_velocity_covariance=cov9, linear_acceleration=vec(0.5, 0.1, 9.81),
        linear_acceleration_covariance=cov9)
    pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=12.5, y=-3.25, z=0.5), orientation=quat(0.0, 0.0, 0.38, 0.925))
    twist = T["geometry_msgs/msg/Twist"](linear=vec(1.2, 0.0, 0.0), angular=vec(0.0, 0.0, 0.1))
    yield "odometry", "nav_msgs/msg/Odometry", T["nav_msgs/msg/Odometry"](
        header=header(1700000002, 999, "odom"), child_frame_id="base_link",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov36),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov36))
    tf = lambda child, x: T["geometry_msgs/msg/TransformStamped"](
        header=header(0, 0, "base_link"), child_frame_id=child,
        transform=T["geometry_msgs/msg/Transform"](translation=vec(x, 0.0, 1.1), rotation=quat(0.0, 0.0, 0.0, 1.0)))
    yield "tf_static", "tf2_msgs/msg/TFMessage", T["tf2_msgs/msg/TFMessage"](transforms=[tf("os_sensor", 0.2), tf("gps", -0.3)])
    info = T["nav_msgs/msg/MapMetaData"](map_load_time=T["builtin_interfaces/msg/Time"](sec=3, nanosec=4),
                                         resolution=0.05, width=3, height=2, origin=pose)
    yield "occupancy_grid", "nav_msgs/msg/OccupancyGrid", T["nav_msgs/msg/OccupancyGrid"](
        header=header(7, 8, "map"), info=info, data=np.array([-1, 0, 100, 50, 0, -1], dtype=np.int8))
    yield from clouds()


def clouds():
    """An Ouster-like unorganized cloud (x, y, z, intensity f32, t u32 ns, ring u16, padded
    to 32 bytes) and a Velodyne-like one (f32 time in s, big endian, f64 z)."""
    rng = np.random.default_rng(5)
    n = 37
    Field = T["sensor_msgs/msg/PointField"]
    ouster = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("pad", "<f4"),
                                ("intensity", "<f4"), ("t", "<u4"), ("ring", "<u2"), ("pad2", "V6")])
    ouster["x"], ouster["y"], ouster["z"] = rng.normal(size=(3, n)) * 10
    ouster["x"][3] = np.nan
    ouster["t"] = np.arange(n) * 48828
    ouster["ring"] = np.arange(n) % 128
    fields = [Field(name="x", offset=0, datatype=7, count=1), Field(name="y", offset=4, datatype=7, count=1),
              Field(name="z", offset=8, datatype=7, count=1), Field(name="intensity", offset=16, datatype=7, count=1),
              Field(name="t", offset=20, datatype=6, count=1), Field(name="ring", offset=24, datatype=4, count=1)]
    yield cloud("cloud_ouster", ouster, fields, False, False, (1700000003, 500), "t", 1)
    velo = np.zeros(n, dtype=[("x", ">f4"), ("y", ">f4"), ("z", ">f8"), ("ring", ">u2"), ("time", ">f4")])
    velo["x"], velo["y"], velo["z"] = rng.normal(size=(3, n)) * 10
    velo["ring"] = np.arange(n) % 16
    velo["time"] = -0.1 + np.arange(n) * 1e-3
    fields = [Field(name="x", offset=0, datatype=7, count=1), Field(name="y", offset=4, datatype=7, count=1),
              Field(name="z", offset=8, datatype=8, count=1), Field(name="ring", offset=16, datatype=4, count=1),
              Field(name="time", offset=18, datatype=7, count=1)]
    yield cloud("cloud_velodyne", velo, fields, True, True, (1700000004, 0), "time", 1e9)


def cloud(name, points, fields, big, dense, stamp, time_field, to_ns):
    msg = T["sensor_msgs/msg/PointCloud2"](
        header=header(*stamp, "lidar"), height=1, width=len(points), fields=fields,
        is_bigendian=big, point_step=points.dtype.itemsize, row_step=points.dtype.itemsize * len(points),
        data=np.frombuffer(points.tobytes(), dtype=np.uint8), is_dense=dense)
    expected = {
        "xyz": [[None if np.isnan(v) else float(v) for v in p] for p in zip(points["x"].astype(np.float32), points["y"].astype(np.float32), points["z"].astype(np.float32))],
        "ring": points["ring"].astype(int).tolist(),
        "offset_ns": [int(v) for v in (points[time_field].astype(np.float64) * to_ns).round()],
    }
    return name, "sensor_msgs/msg/PointCloud2", (msg, expected)


def write(out):
    for name, typename, msg in messages():
        expected = None
        if isinstance(msg, tuple):
            msg, expected = msg
        for order, little in (("le", True), ("be", False)):
            (out / f"{name}.{order}.cdr").write_bytes(bytes(ts.serialize_cdr(msg, typename, little_endian=little)))
        body = plain(msg)
        if expected is not None:
            body.pop("data")
            body["points"] = expected
        (out / f"{name}.json").write_text(json.dumps(body))


def read(out):
    types = {"tf_static": "tf2_msgs/msg/TFMessage", "occupancy_grid": "nav_msgs/msg/OccupancyGrid"}
    for path in sorted(out.glob("*.rust.cdr")):
        name = path.name.removesuffix(".rust.cdr")
        msg = ts.deserialize_cdr(path.read_bytes(), types[name])
        (out / f"{name}.rust.json").write_text(json.dumps(plain(msg)))


def hashes(out):
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    names = json.loads((out / "types.json").read_text())
    (out / "hashes.json").write_text(json.dumps({n: jazzy.hash_rihs01(n) for n in names}))


if __name__ == "__main__":
    {"write": write, "read": read, "hashes": hashes}[sys.argv[1]](Path(sys.argv[2]))
