"""Writes a CARMEN log (.clf, .clf.gz: the 2D SLAM benchmark's logs) as a
rosbag2 recording, the way a ROS 2 user converts one, with rosbags (an
independent rosbag2 writer and CDR serializer; its own CARMEN parsing
here, not twindrive's):

  /scan        sensor_msgs/msg/LaserScan in frame `laser`, one per laser
               line (FLASER: 180 degrees ahead; ROBOTLASER1: its start
               angle, step and max_range); readings at or above the
               scanner's "no return" code are +inf (REP-117)
  /odom        nav_msgs/msg/Odometry odom -> base_link (ODOM lines, else
               each laser line's robot pose)      [--odom topic, the default]
  /tf          the same poses as odom -> base_link   [--odom tf, or both]
  /tf_static   base_link -> laser: the laser's pose on the robot
               (robot^-1 (+) laser, from the first laser line)
  /joint_states  sensor_msgs/msg/JointState of two wheels made from the
               same odometry for a robot with --wheel-diameter-m and
               --wheelbase-m: positions (rad, cumulative) or velocities
               (rad/s)                            [--joints positions|velocities]

Header stamps are each line's ipc_timestamp; the bag's receive times its
logger_timestamp. --storage sqlite3 (the default) or mcap.

Perturbations (for testing that a map holds under what a real recording
brings; each drawn from --seed, so a seed gives the same bytes):
  --drop-scans P        leave out each scan with probability P
  --max-range-m R       a lidar with less range: readings beyond R are +inf
  --beam-stride K       every K-th beam only (fewer beams, K times the step)
  --odom-scale S        odometry a little off: each step's translation
                        times S, its rotation times 1/S
  --stamp-jitter-s J    each header stamp moved by a uniform draw in [-J, J]
                        (the receive times keep their order)

usage: carmen_to_bag.py LOG OUT [--storage sqlite3|mcap] [--odom topic|tf|both|none]
         [--joints positions|velocities --wheel-diameter-m D --wheelbase-m B]
         [--drop-scans P] [--max-range-m R] [--beam-stride K] [--odom-scale S]
         [--stamp-jitter-s J] [--seed N] [--until-s T]
"""

import argparse
import gzip
import math
import random
import sys
from collections import Counter
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore


class LogError(Exception):
    pass


def read_log(path: Path):
    """The log's ODOM poses and laser lines, each a dict, in file order."""
    raw = path.read_bytes()
    if raw[:2] == b"\x1f\x8b":
        raw = gzip.decompress(raw)
    odom, lasers = [], []
    for number, line in enumerate(raw.decode("ascii", "replace").splitlines(), 1):
        w = line.split()
        if not w:
            continue
        try:
            if w[0] == "ODOM":
                x, y, th = map(float, w[1:4])
                odom.append({"t": float(w[7]), "logged": float(w[9]), "pose": (x, y, th)})
            elif w[0] == "FLASER":
                n = int(w[1])
                ranges = [float(r) for r in w[2 : 2 + n]]
                rest = w[2 + n :]
                laser = tuple(map(float, rest[0:3]))
                robot = tuple(map(float, rest[3:6]))
                gaps = n - 1 if n % 2 == 1 else n
                lasers.append(
                    {
                        "t": float(rest[6]),
                        "logged": float(rest[8]),
                        "angle_min": -math.pi / 2,
                        "increment": math.pi / gaps,
                        "max_range": None,
                        "ranges": ranges,
                        "laser": laser,
                        "robot": robot,
                    }
                )
            elif w[0] == "ROBOTLASER1":
                start, _fov, res, max_range = map(float, w[2:6])
                n = int(w[8])
                ranges = [float(r) for r in w[9 : 9 + n]]
                k = 9 + n
                k += 1 + int(w[k])  # remissions
                laser = tuple(map(float, w[k : k + 3]))
                robot = tuple(map(float, w[k + 3 : k + 6]))
                k += 11
                lasers.append(
                    {
                        "t": float(w[k]),
                        "logged": float(w[k + 2]),
                        "angle_min": start,
                        "increment": res,
                        "max_range": max_range,
                        "ranges": ranges,
                        "laser": laser,
                        "robot": robot,
                    }
                )
        except (ValueError, IndexError) as e:
            raise LogError(f"{path}:{number}: a {w[0]} line that does not parse ({e})") from e
    if not lasers:
        raise LogError(f"{path}: no FLASER or ROBOTLASER1 line")
    return odom, lasers


def no_return_from(lasers) -> float:
    """The scanner's "no return" code: the lowest reading within 10 % of the
    top that repeats as a plateau (a SICK's 81.83 and 81.91 m), capped by
    ROBOTLASER1's max_range."""
    counts = Counter(r for l in lasers for r in l["ranges"])
    total = sum(counts.values())
    top = max(counts)
    plateau = [r for r, n in counts.items() if r >= 0.9 * top and n >= 10 and n >= 1e-3 * total]
    limit = min(plateau) - 0.01 if plateau else top + 0.01
    caps = [l["max_range"] for l in lasers if l["max_range"] is not None]
    return min([limit] + caps)


def relative(a, b):
    """b seen from a (x, y, heading)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    dth = math.atan2(math.sin(b[2] - a[2]), math.cos(b[2] - a[2]))
    return (c * dx + s * dy, -s * dx + c * dy, dth)


def compose(a, d):
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * d[0] - s * d[1], a[1] + s * d[0] + c * d[1], a[2] + d[2])


def stamp(ts, t: float):
    sec = math.floor(t)
    return ts.types["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=int(round((t - sec) * 1e9)) % 1_000_000_000)


def quaternion(ts, heading: float):
    return ts.types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(heading / 2), w=math.cos(heading / 2))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("log", type=Path)
    p.add_argument("out", type=Path)
    p.add_argument("--storage", choices=["sqlite3", "mcap"], default="sqlite3")
    p.add_argument("--odom", choices=["topic", "tf", "both", "none"], default="topic")
    p.add_argument("--joints", choices=["positions", "velocities"])
    p.add_argument("--wheel-diameter-m", type=float)
    p.add_argument("--wheelbase-m", type=float)
    p.add_argument("--drop-scans", type=float, default=0.0)
    p.add_argument("--max-range-m", type=float)
    p.add_argument("--beam-stride", type=int, default=1)
    p.add_argument("--odom-scale", type=float, default=1.0)
    p.add_argument("--stamp-jitter-s", type=float, default=0.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--until-s", type=float)
    a = p.parse_args()
    if a.joints and not (a.wheel_diameter_m and a.wheelbase_m):
        p.error("--joints needs --wheel-diameter-m and --wheelbase-m")
    if a.beam_stride < 1 or not 0.0 <= a.drop_scans < 1.0 or a.odom_scale <= 0.0:
        p.error("--beam-stride is at least 1, --drop-scans in [0, 1), --odom-scale positive")
    try:
        odom, lasers = read_log(a.log)
    except (OSError, LogError) as e:
        print(f"carmen_to_bag: {e}", file=sys.stderr)
        return 1
    rng = random.Random(a.seed)
    no_return = no_return_from(lasers)
    odom.sort(key=lambda o: o["t"])
    lasers.sort(key=lambda l: l["t"])
    first_t = lasers[0]["t"]
    if a.until_s is not None:
        lasers = [l for l in lasers if l["t"] - first_t <= a.until_s]
        last = lasers[-1]["t"]
        odom = [o for o in odom if o["t"] <= last + 1.0]
    motion = odom or [{"t": l["t"], "logged": l["logged"], "pose": l["robot"]} for l in lasers]
    mount = relative(lasers[0]["robot"], lasers[0]["laser"])

    # Odometry a little off: re-integrate each step scaled.
    if a.odom_scale != 1.0:
        pose = motion[0]["pose"]
        scaled = [dict(motion[0])]
        for prev, cur in zip(motion, motion[1:]):
            d = relative(prev["pose"], cur["pose"])
            pose = compose(pose, (d[0] * a.odom_scale, d[1] * a.odom_scale, d[2] / a.odom_scale))
            scaled.append({**cur, "pose": pose})
        motion = scaled

    ts = get_typestore(Stores.ROS2_HUMBLE)
    LaserScan = ts.types["sensor_msgs/msg/LaserScan"]
    Odometry = ts.types["nav_msgs/msg/Odometry"]
    TFMessage = ts.types["tf2_msgs/msg/TFMessage"]
    JointState = ts.types["sensor_msgs/msg/JointState"]
    Header = ts.types["std_msgs/msg/Header"]
    T = ts.types["geometry_msgs/msg/TransformStamped"]
    Transform = ts.types["geometry_msgs/msg/Transform"]
    Vector3 = ts.types["geometry_msgs/msg/Vector3"]
    Pose = ts.types["geometry_msgs/msg/Pose"]
    Point = ts.types["geometry_msgs/msg/Point"]
    PoseCov = ts.types["geometry_msgs/msg/PoseWithCovariance"]
    TwistCov = ts.types["geometry_msgs/msg/TwistWithCovariance"]
    Twist = ts.types["geometry_msgs/msg/Twist"]

    def header(t, frame):
        return Header(stamp=stamp(ts, t), frame_id=frame)

    def transform(t, parent, child, p, z=0.0):
        return T(
            header=header(t, parent),
            child_frame_id=child,
            transform=Transform(
                translation=Vector3(x=p[0], y=p[1], z=z), rotation=quaternion(ts, p[2])
            ),
        )

    messages = []  # (receive time ns, topic, message)

    def jitter():
        return rng.uniform(-a.stamp_jitter_s, a.stamp_jitter_s) if a.stamp_jitter_s else 0.0

    for l in lasers:
        if a.drop_scans and rng.random() < a.drop_scans:
            continue
        limit = no_return if a.max_range_m is None else min(no_return, a.max_range_m)
        ranges = [r if r < limit else math.inf for r in l["ranges"][:: a.beam_stride]]
        step = l["increment"] * a.beam_stride
        msg = LaserScan(
            header=header(l["t"] + jitter(), "laser"),
            angle_min=l["angle_min"],
            angle_max=l["angle_min"] + step * (len(ranges) - 1),
            angle_increment=step,
            time_increment=0.0,
            scan_time=0.0,
            range_min=0.0,
            range_max=limit,
            ranges=np.array(ranges, dtype=np.float32),
            intensities=np.array([], dtype=np.float32),
        )
        messages.append((int(round(l["logged"] * 1e9)), "/scan", msg))

    zeros = np.zeros(36, dtype=np.float64)
    wheels = [0.0, 0.0]
    for k, m in enumerate(motion):
        t = m["t"] + jitter()
        p = m["pose"]
        recv = int(round(m["logged"] * 1e9))
        if a.odom in ("topic", "both"):
            messages.append(
                (
                    recv,
                    "/odom",
                    Odometry(
                        header=header(t, "odom"),
                        child_frame_id="base_link",
                        pose=PoseCov(
                            pose=Pose(position=Point(x=p[0], y=p[1], z=0.0), orientation=quaternion(ts, p[2])),
                            covariance=zeros,
                        ),
                        twist=TwistCov(
                            twist=Twist(linear=Vector3(x=0.0, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.0)),
                            covariance=zeros,
                        ),
                    ),
                )
            )
        if a.odom in ("tf", "both"):
            messages.append((recv, "/tf", TFMessage(transforms=[transform(t, "odom", "base_link", p)])))
        if a.joints:
            r = a.wheel_diameter_m / 2
            velocities = [0.0, 0.0]
            if k > 0:
                d = relative(motion[k - 1]["pose"], p)
                ds, dth = d[0], d[2]
                step = [(ds - dth * a.wheelbase_m / 2) / r, (ds + dth * a.wheelbase_m / 2) / r]
                dt = m["t"] - motion[k - 1]["t"]
                wheels = [wheels[0] + step[0], wheels[1] + step[1]]
                velocities = [s / dt if dt > 0 else 0.0 for s in step]
            positions = wheels if a.joints == "positions" else []
            messages.append(
                (
                    recv,
                    "/joint_states",
                    JointState(
                        header=header(t, ""),
                        name=["wheel_left_joint", "wheel_right_joint"],
                        position=np.array(positions, dtype=np.float64),
                        velocity=np.array(velocities if a.joints == "velocities" else [], dtype=np.float64),
                        effort=np.array([], dtype=np.float64),
                    ),
                )
            )

    static = TFMessage(transforms=[transform(first_t, "base_link", "laser", mount, z=0.3)])
    start_ns = min(m[0] for m in messages)
    messages.append((start_ns, "/tf_static", static))
    messages.sort(key=lambda m: m[0])

    storage = StoragePlugin.MCAP if a.storage == "mcap" else StoragePlugin.SQLITE3
    types = {
        "/scan": LaserScan.__msgtype__,
        "/odom": Odometry.__msgtype__,
        "/tf": TFMessage.__msgtype__,
        "/tf_static": TFMessage.__msgtype__,
        "/joint_states": JointState.__msgtype__,
    }
    used = {m[1] for m in messages}
    with Writer(a.out, version=9, storage_plugin=storage) as w:
        conns = {}
        for topic in sorted(used):
            conns[topic] = w.add_connection(topic, types[topic], typestore=ts)
        for recv, topic, msg in messages:
            w.write(conns[topic], recv, ts.serialize_cdr(msg, types[topic]))
    print(
        f"{a.out}: {sum(1 for m in messages if m[1] == '/scan')} scans, {len(motion)} odometry poses, "
        f"no return from {no_return:.2f} m, mount ({mount[0]:.3f}, {mount[1]:.3f}, {mount[2]:.3f})",
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
