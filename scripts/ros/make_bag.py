"""Writes a rosbag2 recording of a twindrive simulator log with an
independent ROS 2 implementation, as a robot's own recorder would: the
wheels as sensor_msgs/msg/JointState and a motion-capture reference, on two
clocks.

  --writer rosbags    rosbags' rosbag2 writer (metadata version 9) and CDR
                      serializer: /joint_states with joint positions (rad),
                      the reference as a /tf child frame `robot` of `world`
                      (beside an odom -> base_link transform).
  --writer mcap_ros2  Foxglove's mcap-ros2-support writer, one .mcap file:
                      /joint_states with joint velocities only (rad/s), the
                      reference as geometry_msgs/msg/PoseStamped on
                      /mocap/pose.
  --scans             (rosbags only) also the log's lidar (its first range
                      sensor of kind "lidar") as
                      sensor_msgs/msg/LaserScan on /scan in frame `laser`,
                      its gyro as sensor_msgs/msg/Imu on /imu in frame
                      `imu_link`, and /tf_static with the lidar's mount as a
                      two-link chain base_link -> base_scan (the offset, 10 cm
                      up) -> laser (the yaw), and base_link -> imu_link.

Header stamps: the reference on the capture system's clock (Unix time
1.7e9 s + log time), the joints on the robot's clock, --robot-clock-lag-s
behind it.

usage: make_bag.py LOG_DIR OUT --writer rosbags|mcap_ros2 [--robot-clock-lag-s S] [--scans]
"""

import argparse
import csv
import math
from pathlib import Path

from rosbags.typesys import Stores, get_typestore

EPOCH_NS = 1_700_000_000 * 1_000_000_000
JOINTS = ["wheel_left_joint", "wheel_right_joint"]


def read_log(log_dir: Path):
    """(t_ns, left_rad, right_rad, left_rad_s, right_rad_s) at encoder samples,
    (t_ns, x, y, theta) at tracker samples."""
    import json

    meta = json.loads((log_dir / "log.meta.json").read_text())
    k = 2 * math.pi / meta["ticks_per_rev"]
    wheels, poses = [], []
    with open(log_dir / "log.csv", newline="") as f:
        for row in csv.DictReader(f):
            t_ns = round(float(row["t"]) * 1e9)
            if row["left_ticks"]:
                wheels.append((t_ns, int(row["left_ticks"]) * k, int(row["right_ticks"]) * k,
                               float(row["left_rad_s"]), float(row["right_rad_s"])))
            if row["tracker_x"]:
                poses.append((t_ns, float(row["tracker_x"]), float(row["tracker_y"]),
                               float(row["tracker_theta"])))
    return wheels, poses


def read_sensors(log_dir: Path):
    """The lidar's description and (t_ns, ranges) at its samples, and
    (t_ns, z_rad_s) at the gyro's."""
    import json

    meta = json.loads((log_dir / "log.meta.json").read_text())
    # Logs written before sensors had a kind: a fan of beams is a lidar.
    lidar = next(s for s in meta["range_sensors"]
                 if s.get("kind", "ranger" if s["beams"] == 1 else "lidar") == "lidar")
    cols = [f"range_{lidar['name']}_{i}" for i in range(lidar["beams"])]
    scans, gyro = [], []
    with open(log_dir / "log.csv", newline="") as f:
        for row in csv.DictReader(f):
            t_ns = round(float(row["t"]) * 1e9)
            if row[cols[0]] not in ("", "nan", "NaN"):
                scans.append((t_ns, [float(row[c]) for c in cols]))
            if row.get("gyro_z_rad_s"):
                gyro.append((t_ns, float(row["gyro_z_rad_s"])))
    return lidar, scans, gyro


def stamp(ns: int):
    return ns // 1_000_000_000, ns % 1_000_000_000


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("log_dir", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--writer", choices=["rosbags", "mcap_ros2"], required=True)
    ap.add_argument("--robot-clock-lag-s", type=float, default=0.0)
    ap.add_argument("--scans", action="store_true")
    a = ap.parse_args()
    wheels, poses = read_log(a.log_dir)
    lag_ns = round(a.robot_clock_lag_s * 1e9)
    store = get_typestore(Stores.ROS2_JAZZY)
    if a.scans and a.writer != "rosbags":
        ap.error("--scans needs --writer rosbags")
    if a.writer == "rosbags":
        sensors = read_sensors(a.log_dir) if a.scans else None
        write_rosbags(a.out, store, wheels, poses, lag_ns, sensors)
    else:
        write_mcap_ros2(a.out, store, wheels, poses, lag_ns)


def write_rosbags(out: Path, store, wheels, poses, lag_ns, sensors=None):
    from rosbags.rosbag2 import StoragePlugin, Writer

    T = store.types
    Time = T["builtin_interfaces/msg/Time"]
    Header = T["std_msgs/msg/Header"]
    JointState = T["sensor_msgs/msg/JointState"]
    TFMessage = T["tf2_msgs/msg/TFMessage"]
    TransformStamped = T["geometry_msgs/msg/TransformStamped"]
    Transform = T["geometry_msgs/msg/Transform"]
    Vector3 = T["geometry_msgs/msg/Vector3"]
    Quaternion = T["geometry_msgs/msg/Quaternion"]
    import numpy as np

    def header(ns, frame):
        s, n = stamp(ns)
        return Header(stamp=Time(sec=s, nanosec=n), frame_id=frame)

    def transform(ns, parent, child, x, y, th):
        return TransformStamped(
            header=header(ns, parent), child_frame_id=child,
            transform=Transform(translation=Vector3(x=x, y=y, z=0.0),
                                rotation=Quaternion(x=0.0, y=0.0, z=math.sin(th / 2), w=math.cos(th / 2))))

    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        js = w.add_connection("/joint_states", JointState.__msgtype__, typestore=store)
        tf = w.add_connection("/tf", TFMessage.__msgtype__, typestore=store)
        events = []
        for (t, l, r, _, _) in wheels:
            robot_ns = EPOCH_NS + t - lag_ns
            msg = JointState(header=header(robot_ns, ""), name=JOINTS,
                             position=np.array([l, r]), velocity=np.array([], dtype=np.float64),
                             effort=np.array([], dtype=np.float64))
            events.append((EPOCH_NS + t, 0, js, store.serialize_cdr(msg, JointState.__msgtype__)))
        for (t, x, y, th) in poses:
            ns = EPOCH_NS + t
            msg = TFMessage(transforms=[transform(ns, "odom", "base_link", 0.1, 0.2, 0.3),
                                        transform(ns, "world", "robot", x, y, th)])
            events.append((ns, 1, tf, store.serialize_cdr(msg, TFMessage.__msgtype__)))
        if sensors is not None:
            events.extend(sensor_events(w, store, sensors, lag_ns, header, transform))
        events.sort(key=lambda e: (e[0], e[1]))
        for t, _, conn, raw in events:
            w.write(conn, t, raw)


def sensor_events(w, store, sensors, lag_ns, header, transform):
    """/scan, /imu and /tf_static messages, serialized by rosbags."""
    import numpy as np

    T = store.types
    LaserScan = T["sensor_msgs/msg/LaserScan"]
    Imu = T["sensor_msgs/msg/Imu"]
    TFMessage = T["tf2_msgs/msg/TFMessage"]
    Vector3 = T["geometry_msgs/msg/Vector3"]
    Quaternion = T["geometry_msgs/msg/Quaternion"]
    lidar, scans, gyro = sensors
    beams = lidar["beams"]
    if lidar["fov_rad"] >= 2 * math.pi - 1e-9:
        angle_min, inc = -math.pi, 2 * math.pi / beams
    else:
        angle_min, inc = -0.5 * lidar["fov_rad"], lidar["fov_rad"] / (beams - 1)
    sc = w.add_connection("/scan", LaserScan.__msgtype__, typestore=store)
    im = w.add_connection("/imu", Imu.__msgtype__, typestore=store)
    st = w.add_connection("/tf_static", TFMessage.__msgtype__, typestore=store)
    m = lidar["mount"]
    first = EPOCH_NS + (scans[0][0] if scans else 0)
    # The mount as a chain: the offset (10 cm up), then the yaw.
    offset = transform(first, "base_link", "base_scan", m["x_m"], m["y_m"], 0.0)
    offset.transform.translation.z = 0.1
    events = [(first - 1, 2, st, store.serialize_cdr(TFMessage(transforms=[
        offset,
        transform(first, "base_scan", "laser", 0.0, 0.0, m["heading_rad"]),
        transform(first, "base_link", "imu_link", 0.0, 0.0, 0.0),
    ]), TFMessage.__msgtype__))]
    for (t, ranges) in scans:
        ns = EPOCH_NS + t - lag_ns
        msg = LaserScan(header=header(ns, "laser"), angle_min=angle_min,
                        angle_max=angle_min + inc * (beams - 1), angle_increment=inc,
                        time_increment=0.0, scan_time=0.1, range_min=lidar["min_range_m"],
                        range_max=lidar["max_range_m"], ranges=np.array(ranges, dtype=np.float32),
                        intensities=np.array([], dtype=np.float32))
        events.append((EPOCH_NS + t, 3, sc, store.serialize_cdr(msg, LaserScan.__msgtype__)))
    unknown = np.zeros(9)
    unknown[0] = -1.0
    for (t, z) in gyro:
        ns = EPOCH_NS + t - lag_ns
        msg = Imu(header=header(ns, "imu_link"),
                  orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=unknown,
                  angular_velocity=Vector3(x=0.0, y=0.0, z=z), angular_velocity_covariance=np.zeros(9),
                  linear_acceleration=Vector3(x=0.0, y=0.0, z=0.0),
                  linear_acceleration_covariance=unknown)
        events.append((EPOCH_NS + t, 4, im, store.serialize_cdr(msg, Imu.__msgtype__)))
    return events


def write_mcap_ros2(out: Path, store, wheels, poses, lag_ns):
    from mcap_ros2.writer import Writer

    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out, "wb") as f:
        w = Writer(f)
        js = w.register_msgdef("sensor_msgs/msg/JointState",
                               store.generate_msgdef("sensor_msgs/msg/JointState", ros_version=2)[0])
        ps = w.register_msgdef("geometry_msgs/msg/PoseStamped",
                               store.generate_msgdef("geometry_msgs/msg/PoseStamped", ros_version=2)[0])
        events = []
        for (t, _, _, vl, vr) in wheels:
            s, n = stamp(EPOCH_NS + t - lag_ns)
            events.append((EPOCH_NS + t, "/joint_states", js, {
                "header": {"stamp": {"sec": s, "nanosec": n}, "frame_id": ""},
                "name": JOINTS, "position": [], "velocity": [vl, vr], "effort": []}))
        for (t, x, y, th) in poses:
            s, n = stamp(EPOCH_NS + t)
            events.append((EPOCH_NS + t, "/mocap/pose", ps, {
                "header": {"stamp": {"sec": s, "nanosec": n}, "frame_id": "world"},
                "pose": {"position": {"x": x, "y": y, "z": 0.0},
                         "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(th / 2), "w": math.cos(th / 2)}}}))
        events.sort(key=lambda e: e[0])
        for t, topic, schema, msg in events:
            w.write_message(topic=topic, schema=schema, message=msg, log_time=t, publish_time=t)
        w.finish()


if __name__ == "__main__":
    main()
