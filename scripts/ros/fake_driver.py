"""A ROS 2 robot's drivers without ROS: a site's physics behind zenoh,
speaking rmw_zenoh as a TurtleBot-class robot running `rmw_zenoh_cpp` would.
The physics is twindrive's site simulator (`twindrive site-sim`, the
default) or, with --physics mujoco, the MuJoCo physics engine
(`mujoco_site.py`: motors with a gain and a torque limit, inertia, tyre and
caster friction, ray-cast range sensors, a bumper from contacts; a site
drawn from a map is built from its map, --map-window X0,Y0,X1,Y1 keeps to
a part of it). Every byte on the wire is made by an
independent implementation: CDR and RIHS01 type hashes by `rosbags`, the
session by `eclipse-zenoh`.

Publishes (rmw_zenoh key expressions, 33-byte attachments, liveliness
tokens for the node and each publisher and subscription):
  /joint_states      sensor_msgs/msg/JointState (wheel_left_joint, wheel_right_joint)
  /odom              nav_msgs/msg/Odometry (the simulator's true pose)
  /<sensor>          sensor_msgs/msg/Range or LaserScan per range sensor, at its rate_hz
  /hazard_detection  irobot_create_msgs/msg/HazardDetectionVector (BUMP, STALL)
Subscribes /cmd_vel (geometry_msgs/msg/Twist) like a diff_drive_controller:
wheel speeds from the twist through --wheel-radius/--wheel-separation, zero
when no command came for --cmd-timeout (0: never, as a motor controller that
holds the last command it heard).

--stall-joints-after S stops /joint_states S seconds after the robot first
moved (a driver that hangs). At the end (--run-for, or SIGTERM) it writes
--stats: commands received, their attachments, the speeds commanded after
the stall, every command as received (`received`: [s since start, v, w]),
the robot at every tick (`ticks`: [s, left, right rad/s driven, x, y,
heading]), the ticks with a contact (`contact_ticks`), with MuJoCo how far
the robot rolls to a stop from its speed at the last moving command
(`braking`) and the model's geom count (`geoms`), and the liveliness
tokens on the network.

usage: fake_driver.py --connect E --site SITE.toml --twindrive BIN --stats OUT.json [...]
"""

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
import tomllib
import traceback

import numpy as np
import zenoh
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from check_bag import IROBOT
from mujoco_site import MujocoSite, parse_window

NODE = "fake_driver"


def dds_name(msgtype: str) -> str:
    pkg, kind, name = msgtype.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


class Ros:
    """An rmw_zenoh node: keys, tokens, attachments."""

    def __init__(self, session, store, domain=0):
        self.session = session
        self.store = store
        self.domain = domain
        self.zid = str(session.info.zid())
        self.next_id = 1
        self.tokens = [session.liveliness().declare_token(
            f"@ros2_lv/{domain}/{self.zid}/0/0/NN/%/%/{NODE}")]

    def _token(self, kind, topic, msgtype, depth=10):
        entity = self.next_id
        self.next_id += 1
        h = self.store.hash_rihs01(msgtype)
        key = (f"@ros2_lv/{self.domain}/{self.zid}/0/{entity}/{kind}/%/%/{NODE}/"
               f"{topic.replace('/', '%')}/{dds_name(msgtype)}/{h}/::,{depth}:,:,:,,")
        self.tokens.append(self.session.liveliness().declare_token(key))
        return key

    def key(self, topic, msgtype):
        return f"{self.domain}/{topic.strip('/')}/{dds_name(msgtype)}/{self.store.hash_rihs01(msgtype)}"

    def publisher(self, topic, msgtype):
        token = self._token("MP", topic, msgtype)
        pub = self.session.declare_publisher(self.key(topic, msgtype))
        gid = bytes(range(16))
        seq = [0]

        def put(msg):
            seq[0] += 1
            attachment = (seq[0].to_bytes(8, "little", signed=True)
                          + time.time_ns().to_bytes(8, "little", signed=True)
                          + bytes([16]) + gid)
            pub.put(bytes(self.store.serialize_cdr(msg, msgtype)), attachment=attachment)
        return put, token

    def subscriber(self, topic, msgtype, callback):
        self._token("MS", topic, msgtype)
        key = f"{self.domain}/{topic.strip('/')}/{dds_name(msgtype)}/*"
        return self.session.declare_subscriber(key, callback)


class SiteSim:
    """`twindrive site-sim` behind a pipe."""

    def __init__(self, twindrive, site):
        self.proc = subprocess.Popen([twindrive, "site-sim", "--site", site], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, text=True)

    def step(self, left, right, steps, ranges=True):
        self.proc.stdin.write(f"{left!r} {right!r} {steps}\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        return json.loads(line) if line else None

    def close(self):
        # The site simulator goes with the driver, however the driver ends.
        if self.proc.poll() is None:
            self.proc.stdin.close()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        self.proc.wait()


def braking(sim, stats):
    """The robot's speed at the last moving command it heard, and how far
    the physics lets it roll to a stop from there."""
    moving = [r for r in stats["received"] if r[1] != 0.0 or r[2] != 0.0]
    if not moving:
        return None
    t = moving[-1][0]
    ticks = stats["ticks"]
    speeds = [math.hypot(b[3] - a[3], b[4] - a[4]) / (b[0] - a[0])
              for a, b in zip(ticks, ticks[1:]) if t - 0.2 <= b[0] <= t and b[0] > a[0]]
    speed = max(speeds, default=0.0)
    return {"at_s": t, "speed_m_s": speed, "distance_m": sim.braking_distance_m(speed)}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--connect", required=True)
    ap.add_argument("--site", required=True)
    ap.add_argument("--twindrive", required=True)
    ap.add_argument("--stats", required=True)
    ap.add_argument("--rate", type=float, default=50.0)
    ap.add_argument("--cmd-timeout", type=float, default=0.5,
                    help="zero the wheels after this long without a command (s); 0: never")
    ap.add_argument("--wheel-radius", type=float)
    ap.add_argument("--wheel-separation", type=float)
    ap.add_argument("--stall-joints-after", type=float)
    ap.add_argument("--run-for", type=float, default=600.0)
    ap.add_argument("--physics", choices=["site-sim", "mujoco"], default="site-sim")
    ap.add_argument("--seed", type=int, default=0, help="MuJoCo's sensor noise")
    ap.add_argument("--map-window", type=parse_window,
                    help="X0,Y0,X1,Y1 (m): MuJoCo builds only this part of the site's map")
    a = ap.parse_args()

    with open(a.site, "rb") as f:
        site = tomllib.load(f)
    nominal = site["robot"]["nominal_params"]
    radius = a.wheel_radius or 0.25 * (nominal["left_diameter_m"] + nominal["right_diameter_m"])
    separation = a.wheel_separation or nominal["wheelbase_m"]
    dt = site["simulation"]["dt_s"]
    period = 1.0 / a.rate
    steps = max(1, round(period / dt))
    sensors = site.get("range_sensors", [])

    store = get_typestore(Stores.ROS2_JAZZY)
    for name, text in IROBOT.items():
        store.register(get_types_from_msg(text, name))
    T = store.types

    conf = zenoh.Config()
    # A client of the router: every sample goes through it. (Two peers
    # that also meet directly through gossip lost a whole run's samples
    # once on a loaded machine.)
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([a.connect]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)
    ros = Ros(session, store)

    lock = threading.Lock()
    stats = {"commands": 0, "bad_attachments": 0, "decode_errors": 0, "sequence_numbers": [],
             "after_stall": [], "moving_commands": 0, "stalled_at_s": None,
             "received": [], "ticks": [], "contact_ticks": 0, "physics": a.physics}
    cmd = {"v": 0.0, "w": 0.0, "at": -1e9}
    started = time.monotonic()

    def on_cmd(sample):
        now = time.monotonic()
        att = sample.attachment
        with lock:
            try:
                t = store.deserialize_cdr(bytes(sample.payload.to_bytes()), "geometry_msgs/msg/Twist")
            except Exception:  # noqa: BLE001 - garbage on the wire is counted, not fatal
                stats["decode_errors"] += 1
                return
            raw = bytes(att.to_bytes()) if att is not None else b""
            if len(raw) != 33 or raw[16] != 16:
                stats["bad_attachments"] += 1
            else:
                stats["sequence_numbers"].append(int.from_bytes(raw[:8], "little", signed=True))
            stats["commands"] += 1
            cmd.update(v=t.linear.x, w=t.angular.z, at=now)
            stats["received"].append([now - started, t.linear.x, t.angular.z])
            if abs(t.linear.x) > 1e-9 or abs(t.angular.z) > 1e-9:
                stats["moving_commands"] += 1
            if stats["stalled_at_s"] is not None:
                stats["after_stall"].append([now - stats["stalled_at_s"], t.linear.x, t.angular.z])

    _sub = ros.subscriber("/cmd_vel", "geometry_msgs/msg/Twist", on_cmd)
    pub_joints, _ = ros.publisher("/joint_states", "sensor_msgs/msg/JointState")
    pub_odom, _ = ros.publisher("/odom", "nav_msgs/msg/Odometry")
    pub_hazard, _ = ros.publisher("/hazard_detection", "irobot_create_msgs/msg/HazardDetectionVector")
    pub_ranges = []
    for s in sensors:
        # The sensor's kind as the site says it; a site written before
        # `kind` existed means a ranger for one beam (as twindrive reads it).
        ranger = s.get("kind", "ranger" if s.get("beams", 1) == 1 else "lidar") == "ranger"
        kind = "sensor_msgs/msg/Range" if ranger else "sensor_msgs/msg/LaserScan"
        # Published at the sensor's rate (every tick without one), as the
        # twin samples it: a 5 Hz lidar every tenth tick at 50 Hz.
        every = max(1, round(a.rate / s["rate_hz"])) if s.get("rate_hz") else 1
        pub_ranges.append((s, kind, ros.publisher("/" + s["name"], kind)[0], every))

    if a.physics == "mujoco":
        sim = MujocoSite(site, a.seed, base_dir=os.path.dirname(os.path.abspath(a.site)),
                         map_window=a.map_window)
    else:
        sim = SiteSim(a.twindrive, a.site)
    try:
        stop = threading.Event()
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
        signal.signal(signal.SIGINT, lambda *_: stop.set())

        def header(frame):
            ns = time.time_ns()
            return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
                sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id=frame)

        moved_at = None
        tick = 0
        next_tick = started
        announced = False
        while not stop.is_set() and time.monotonic() - started < a.run_for:
            now = time.monotonic()
            with lock:
                fresh = a.cmd_timeout <= 0 or now - cmd["at"] <= a.cmd_timeout
                v, w = (cmd["v"], cmd["w"]) if fresh else (0.0, 0.0)
            left = (v - 0.5 * w * separation) / radius
            right = (v + 0.5 * w * separation) / radius
            due = [tick % every == 0 for _, _, _, every in pub_ranges]
            tick += 1
            s = sim.step(left, right, steps, ranges=any(due))
            if s is None:
                break
            if moved_at is None and (abs(left) > 1e-9 or abs(right) > 1e-9):
                moved_at = now
            stalled = a.stall_joints_after is not None and moved_at is not None \
                and now - moved_at > a.stall_joints_after
            if stalled and stats["stalled_at_s"] is None:
                with lock:
                    stats["stalled_at_s"] = now
            if not stalled:
                pub_joints(T["sensor_msgs/msg/JointState"](
                    header=header(""), name=["wheel_left_joint", "wheel_right_joint"],
                    position=np.array(s["wheel_rad"], dtype=np.float64),
                    velocity=np.array(s["wheel_rad_s"], dtype=np.float64),
                    effort=np.array([], dtype=np.float64)))
                if not announced:
                    # Said once, for the driver's log (the tests start a
                    # mission once the agent says it heard the joints).
                    print("publishing joint states", file=sys.stderr, flush=True)
                    announced = True
            x, y, th = s["pose"]
            with lock:
                stats["ticks"].append([now - started, left, right, x, y, th])
                stats["contact_ticks"] += int(s["bump"] or s["blocked"])
            P = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(th / 2), w=math.cos(th / 2)))
            pub_odom(T["nav_msgs/msg/Odometry"](
                header=header("odom"), child_frame_id="base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=P, covariance=np.zeros(36)),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](
                        linear=T["geometry_msgs/msg/Vector3"](x=v, y=0.0, z=0.0),
                        angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=w)),
                    covariance=np.zeros(36))))
            detections = []
            HD = T["irobot_create_msgs/msg/HazardDetection"]
            if s["bump"]:
                detections.append(HD(header=header("bump_front"), type=1))
            if s["blocked"]:
                detections.append(HD(header=header("base_link"), type=3))
            pub_hazard(T["irobot_create_msgs/msg/HazardDetectionVector"](header=header("base_link"), detections=detections))
            offset = 0
            for (sensor, kind, put, _), publish in zip(pub_ranges, due):
                beams = sensor.get("beams", 1)
                values = [math.inf if r is None else r for r in (s["ranges_m"] or [])[offset:offset + beams]]
                offset += beams
                if not publish:
                    continue
                if kind == "sensor_msgs/msg/Range":
                    put(T[kind](header=header(sensor["name"] + "_link"), radiation_type=1,
                                field_of_view=float(sensor.get("fov_rad", 0.0)),
                                min_range=float(sensor["min_range_m"]), max_range=float(sensor["max_range_m"]),
                                range=float(values[0]), variance=0.0))
                else:
                    fov = float(sensor.get("fov_rad", 2 * math.pi))
                    # twindrive's beam angles: a full circle is beams steps
                    # of 2 pi / beams from -pi (no beam twice at +-pi).
                    if fov >= 2 * math.pi - 1e-9:
                        lo, inc = -math.pi, 2 * math.pi / beams
                    else:
                        lo, inc = -fov / 2, fov / max(beams - 1, 1)
                    put(T[kind](header=header(sensor["name"] + "_link"), angle_min=lo,
                                angle_max=lo + inc * (beams - 1),
                                angle_increment=inc, time_increment=0.0, scan_time=period,
                                range_min=float(sensor["min_range_m"]), range_max=float(sensor["max_range_m"]),
                                ranges=np.array(values, dtype=np.float32), intensities=np.array([], dtype=np.float32)))
            next_tick += period
            time.sleep(max(0.0, next_tick - time.monotonic()))

        # What a `ros2 node list` / `ros2 topic info` would see.
        # On a loaded machine a query can come back empty: ask again (up
        # to 30 s) until the agent's node is among the replies.
        tokens = []
        deadline = time.monotonic() + 30.0
        while True:
            tokens = [str(r.ok.key_expr) for r in session.liveliness().get("@ros2_lv/0/**", timeout=5.0) if r.ok]
            if any("/NN/%/%/twindrive_agent" in t for t in tokens) or time.monotonic() > deadline:
                break
            time.sleep(0.5)
        with lock:
            if a.physics == "mujoco":
                stats["braking"] = braking(sim, stats)
                stats["geoms"] = sim.model.ngeom
            stats["liveliness"] = sorted(tokens)
            stats["type_hashes"] = {t: store.hash_rihs01(t) for t in [
                "geometry_msgs/msg/Twist", "sensor_msgs/msg/JointState", "nav_msgs/msg/Odometry",
                "sensor_msgs/msg/Range", "sensor_msgs/msg/LaserScan",
                "irobot_create_msgs/msg/HazardDetectionVector"]}
            if stats["stalled_at_s"] is not None:
                stats["stalled_at_s"] -= started
            with open(a.stats + ".tmp", "w") as f:
                json.dump(stats, f)
            os.replace(a.stats + ".tmp", a.stats)
    finally:
        sim.close()
        session.close()


if __name__ == "__main__":
    try:
        main()
    except Exception:  # noqa: BLE001 - report, then exit for real
        traceback.print_exc()
        sys.stderr.flush()
        # zenoh's threads would keep a failed driver alive.
        os._exit(1)
