"""A site in MuJoCo: the physics engine as the robot behind the fake ROS 2
driver (`fake_driver.py --physics mujoco`), a fairer robot than twindrive's
own simulator because nothing in it was written by twindrive.

From a twindrive site file it builds:
  - the site's walls (segments, polylines) and blocks (rectangles) as boxes;
  - its occupancy map (`[world] map`, a ROS map_server YAML and its PGM, as
    `twindrive map` writes them), as the twin reads it: every cell that is
    not free (occupied, unknown, and all around the map) is solid, in boxes
    (runs of solid cells along the rows or the columns, merged with the
    same run on the next ones into rectangles): a few thousand for a
    building's floor;
  - a differential-drive robot: a cylindrical chassis of the site's
    footprint, two wheels of the site's *true* diameters on hinges the
    site's true wheelbase apart, each driven by a velocity servo with a
    finite gain and a torque limit (MuJoCo's `velocity` actuator), rotor
    inertia, tyres with rubber-on-floor friction, and two casters that
    drag a little;
  - range sensors by ray casting (`mj_ray`) from each sensor's mount, with
    the site's noise, dropouts, minimum and maximum range;
  - a bumper from contacts: the chassis touching a wall within the bumper's
    arc (detected `contact_margin_m` early, as the site file says).
Encoders read the wheel hinges. Its `step(left, right, steps)` returns what
`twindrive site-sim` prints for one line, so the driver can use either.

Run as a script, it reads the robot's range sensors at poses:

  mujoco_site.py SITE.toml [--map-window X0,Y0,X1,Y1] < POSES

POSES: lines of `x y heading`; for each, the robot is set down there and a
JSON line printed: `pose` (where it settled), `ranges_m` (every beam) and
`geoms` (the model's geom count).
"""

import argparse
import math
import os

import mujoco
import numpy as np
from ruamel.yaml import YAML

WALL_HEIGHT_M = 0.25
WALL_THICKNESS_M = 0.004
CHASSIS_MASS_KG = 2.5
CHASSIS_HALF_HEIGHT_M = 0.03
WHEEL_MASS_KG = 0.08
WHEEL_HALF_WIDTH_M = 0.008
# A small geared DC motor's rotor inertia seen at the wheel (kg m^2).
ROTOR_INERTIA = 2e-5
CASTER_RADIUS_M = 0.01
TYRE_FRICTION = 1.0
CASTER_FRICTION = 0.02
# The casters stand this far off a level floor: the wheels carry the
# robot, and a caster takes its share when the chassis pitches.
CASTER_LIFT_M = 0.0005
TIMESTEP_S = 0.001
# Walls and blocks are in geom group 0 (what rays see), the robot in 1.
WALLS, ROBOT = 0, 1


def _wall_boxes(world, base_dir=".", window=None):
    """(centre x, y, half length, half width, yaw) of every wall and block."""
    boxes = []
    segments = [tuple(map(tuple, s)) for s in world.get("segments", [])]
    for line in world.get("polylines", []):
        pts = [tuple(p) for p in line["points"]]
        if line.get("closed"):
            pts.append(pts[0])
        segments.extend(zip(pts, pts[1:]))
    for (x0, y0), (x1, y1) in segments:
        length = math.hypot(x1 - x0, y1 - y0)
        if length == 0.0:
            continue
        boxes.append(((x0 + x1) / 2, (y0 + y1) / 2,
                      length / 2 + WALL_THICKNESS_M / 2, WALL_THICKNESS_M / 2,
                      math.atan2(y1 - y0, x1 - x0)))
    for r in world.get("rectangles", []):
        (x0, y0), (x1, y1) = r["min"], r["max"]
        boxes.append(((x0 + x1) / 2, (y0 + y1) / 2, (x1 - x0) / 2, (y1 - y0) / 2, 0.0))
    if "map" in world:
        boxes.extend(map_boxes(os.path.join(base_dir, world["map"]), window))
    return boxes


def _read_pgm(path):
    """A binary (P5) or plain (P2) PGM's grey levels scaled to 0-255, row 0
    at the top as in the image."""
    with open(path, "rb") as f:
        data = f.read()
    fields, pos = [], 0
    while len(fields) < 4:
        while pos < len(data) and data[pos:pos + 1].isspace():
            pos += 1
        if data[pos:pos + 1] == b"#":
            pos = data.find(b"\n", pos)
            if pos < 0:
                break
            continue
        start = pos
        while pos < len(data) and not data[pos:pos + 1].isspace():
            pos += 1
        if start == pos:
            break
        fields.append(data[start:pos])
    if len(fields) < 4 or fields[0] not in (b"P5", b"P2"):
        raise ValueError(f"{path}: expected a PGM image (P5 or P2 with width, height and maxval); "
                         "MuJoCo's site reads the maps `twindrive map` writes")
    try:
        width, height, maxval = (int(v) for v in fields[1:4])
    except ValueError:
        raise ValueError(f"{path}: the PGM header's width, height and maxval must be integers, "
                         f"got {[v.decode(errors='replace') for v in fields[1:4]]}") from None
    if width <= 0 or height <= 0 or not 0 < maxval < 65536:
        raise ValueError(f"{path}: a PGM of {width} x {height} pixels with maxval {maxval}: "
                         "expected positive sizes and 0 < maxval < 65536")
    n = width * height
    if fields[0] == b"P5":
        dtype = np.uint8 if maxval < 256 else np.dtype(">u2")
        raw = data[pos + 1:]
        if len(raw) < n * np.dtype(dtype).itemsize:
            raise ValueError(f"{path}: {len(raw)} bytes of pixels, expected "
                             f"{n * np.dtype(dtype).itemsize} for {width} x {height}")
        pixels = np.frombuffer(raw, dtype=dtype, count=n)
    else:
        words = data[pos:].split()
        if len(words) < n:
            raise ValueError(f"{path}: {len(words)} pixels, expected {n} for {width} x {height}")
        pixels = np.array([int(w) for w in words[:n]])
    grey = pixels.astype(np.float64).reshape(height, width)
    return np.round(grey * 255.0 / maxval) if maxval != 255 else grey


def read_map(yaml_path):
    """A ROS map_server map as the twin reads it (twindrive_sim::map):
    (blocked cells, row 0 at the bottom; resolution in m; origin [x, y,
    yaw] of the lower-left pixel). A cell is blocked unless it is free:
    occupied and unknown cells are obstacles."""
    with open(yaml_path, encoding="utf-8") as f:
        meta = YAML(typ="safe").load(f)
    if not isinstance(meta, dict):
        raise ValueError(f"{yaml_path}: expected map_server's fields (image, resolution, origin, ...)")

    def field(name, default=None):
        if name not in meta and default is None:
            raise ValueError(f"{yaml_path}: field `{name}` is missing")
        return meta.get(name, default)

    resolution = field("resolution")
    origin = field("origin")
    if not (isinstance(resolution, (int, float)) and resolution > 0):
        raise ValueError(f"{yaml_path}: field `resolution`: must be > 0 metres per pixel, got {resolution!r}")
    if not (isinstance(origin, list) and len(origin) == 3
            and all(isinstance(v, (int, float)) and math.isfinite(v) for v in origin)):
        raise ValueError(f"{yaml_path}: field `origin`: must be three finite numbers [x, y, yaw], got {origin!r}")
    occupied_thresh = field("occupied_thresh", 0.65)
    free_thresh = field("free_thresh", 0.196)
    negate = field("negate", 0)
    mode = field("mode", "trinary")
    if mode not in ("trinary", "scale", "raw"):
        raise ValueError(f"{yaml_path}: field `mode`: expected trinary, scale or raw, got `{mode}`")
    if not 0.0 <= free_thresh < occupied_thresh <= 1.0:
        raise ValueError(f"{yaml_path}: field `free_thresh`: need 0 <= free_thresh < occupied_thresh <= 1, "
                         f"got {free_thresh} and {occupied_thresh}")
    grey = _read_pgm(os.path.join(os.path.dirname(yaml_path), field("image")))
    if mode == "raw":
        free = grey <= free_thresh * 100.0
    else:
        occupancy = grey / 255.0 if negate else (255.0 - grey) / 255.0
        free = occupancy < free_thresh
    return ~free[::-1], float(resolution), [float(v) for v in origin]


def _rectangles(solid):
    """(row0, row1, col0, col1) rectangles, ends excluded, covering the
    True cells of `solid`: runs along each row, each merged with the same
    run on the row below when there is one."""
    done = []
    open_runs = {}
    for r, row in enumerate(solid):
        edges = np.flatnonzero(np.diff(np.concatenate(([False], row, [False])).astype(np.int8)))
        runs = set(zip(edges[::2].tolist(), edges[1::2].tolist()))
        for run, r0 in list(open_runs.items()):
            if run not in runs:
                done.append((r0, r, *run))
                del open_runs[run]
        for run in runs:
            open_runs.setdefault(run, r)
    done.extend((r0, len(solid), *run) for run, r0 in open_runs.items())
    return sorted(done)


def map_boxes(yaml_path, window=None):
    """(centre x, y, half length, half width, yaw) of boxes over the map's
    solid cells, with a ring of solid cells around the map (beyond it
    nothing is free): runs of solid cells along the rows (or the columns,
    whichever gives fewer boxes), each merged with the same run on the
    next rows. With `window` (x0, y0, x1, y1 in the site's frame, m) only
    the cells whose centres lie in it may be free: the rest are solid, so
    the building ends at the window's edge (a smaller model, faster to ray
    cast, the same as the whole map wherever the sensors reach from the
    robot's way)."""
    blocked, res, (ox, oy, yaw) = read_map(yaml_path)
    c, s = math.cos(yaw), math.sin(yaw)
    if window is not None:
        x0, y0, x1, y1 = window
        rows, cols = np.indices(blocked.shape)
        u, v = (cols + 0.5) * res, (rows + 0.5) * res
        x, y = ox + c * u - s * v, oy + s * u + c * v
        blocked = blocked | (x < x0) | (x > x1) | (y < y0) | (y > y1)
    padded = np.ones((blocked.shape[0] + 2, blocked.shape[1] + 2), dtype=bool)
    padded[1:-1, 1:-1] = blocked
    by_rows = _rectangles(padded)
    by_columns = [(r0, r1, c0, c1) for c0, c1, r0, r1 in _rectangles(padded.T)]
    boxes = []
    for r0, r1, c0, c1 in min(by_rows, by_columns, key=len):
        # Padded cell (col, row) is the map's (col - 1, row - 1).
        u, v = (c0 + c1 - 2) * res / 2, (r0 + r1 - 2) * res / 2
        boxes.append((ox + c * u - s * v, oy + s * u + c * v, (c1 - c0) * res / 2, (r1 - r0) * res / 2, yaw))
    return boxes


def model_xml(site, kv_nm_s, torque_limit_nm, base_dir=".", map_window=None):
    """The MJCF of `site` (a parsed twindrive site file; its map, if any,
    relative to `base_dir`, the site file's directory, and only within
    `map_window`, see `map_boxes`)."""
    robot = site["robot"]
    truth = robot["true_params"]
    r_left, r_right = truth["left_diameter_m"] / 2, truth["right_diameter_m"] / 2
    axle_z = (r_left + r_right) / 2
    half_base = truth["wheelbase_m"] / 2
    footprint = robot["footprint_radius_m"]
    margin = site.get("bump", {}).get("contact_margin_m", 0.0)
    walls = []
    for k, (x, y, hl, hw, yaw) in enumerate(_wall_boxes(site["world"], base_dir, map_window)):
        walls.append(
            f'<geom name="wall{k}" type="box" group="{WALLS}" pos="{x} {y} {WALL_HEIGHT_M / 2}" '
            f'size="{hl} {hw} {WALL_HEIGHT_M / 2}" euler="0 0 {yaw}" rgba=".6 .6 .6 1"/>')
    casters = []
    for name, cx in (("front", footprint - 0.03), ("back", -(footprint - 0.03))):
        casters.append(
            f'<geom name="caster_{name}" type="sphere" group="{ROBOT}" size="{CASTER_RADIUS_M}" '
            f'pos="{cx} 0 {-(axle_z - CASTER_RADIUS_M) + CASTER_LIFT_M}" mass="0.01" '
            f'friction="{CASTER_FRICTION} 0.001 0.0001"/>')
    chassis_z = 0.012 + CHASSIS_HALF_HEIGHT_M - axle_z
    wheels = []
    for name, y, r in (("left", half_base, r_left), ("right", -half_base, r_right)):
        wheels.append(f"""
      <body name="{name}_wheel" pos="0 {y} {r - axle_z}">
        <joint name="{name}" type="hinge" axis="0 1 0" armature="{ROTOR_INERTIA}" damping="1e-4"/>
        <geom name="{name}_tyre" type="cylinder" group="{ROBOT}" size="{r} {WHEEL_HALF_WIDTH_M}"
              euler="{math.pi / 2} 0 0" mass="{WHEEL_MASS_KG}" friction="{TYRE_FRICTION} 0.005 0.0001"/>
      </body>""")
    return f"""
<mujoco model="{site.get('name', 'site')}">
  <compiler angle="radian"/>
  <option timestep="{TIMESTEP_S}" integrator="implicitfast"/>
  <worldbody>
    <!-- MuJoCo takes the larger friction of a pair: the floor's is the
         casters', the tyres' their own. -->
    <geom name="floor" type="plane" group="2" size="0 0 0.05" friction="{CASTER_FRICTION} 0.001 0.0001"/>
    {''.join(walls)}
    <body name="chassis" pos="0 0 {axle_z}">
      <freejoint name="base"/>
      <geom name="chassis" type="cylinder" group="{ROBOT}" size="{footprint} {CHASSIS_HALF_HEIGHT_M}"
            pos="0 0 {chassis_z}" mass="{CHASSIS_MASS_KG}" margin="{margin}" gap="{margin}"/>
      {''.join(casters)}
      {''.join(wheels)}
    </body>
  </worldbody>
  <contact>
    <exclude body1="chassis" body2="left_wheel"/>
    <exclude body1="chassis" body2="right_wheel"/>
  </contact>
  <actuator>
    <velocity name="left" joint="left" kv="{kv_nm_s}" forcelimited="true" forcerange="{-torque_limit_nm} {torque_limit_nm}"/>
    <velocity name="right" joint="right" kv="{kv_nm_s}" forcelimited="true" forcerange="{-torque_limit_nm} {torque_limit_nm}"/>
  </actuator>
</mujoco>
"""


class MujocoSite:
    """The site and its robot in MuJoCo, stepped as `twindrive site-sim` is."""

    def __init__(self, site, seed=0, kv_nm_s=0.08, torque_limit_nm=0.25, base_dir=".", map_window=None):
        """`base_dir`: the site file's directory (its map is relative to
        it); `map_window`: the part of the map to build (`map_boxes`)."""
        self.site = site
        self.dt = site["simulation"]["dt_s"]
        self.kv_nm_s = kv_nm_s
        self.torque_limit_nm = torque_limit_nm
        self.model = mujoco.MjModel.from_xml_string(model_xml(site, kv_nm_s, torque_limit_nm, base_dir, map_window))
        self.data = mujoco.MjData(self.model)
        self.rng = np.random.default_rng(seed)
        self.substeps = max(1, round(self.dt / TIMESTEP_S))
        m = self.model
        self.chassis_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "chassis")
        self.chassis_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "chassis")
        self.joint_q = [m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)]
                        for n in ("left", "right")]
        self.joint_v = [m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)]
                        for n in ("left", "right")]
        self.wall_geoms = {g for g in range(m.ngeom) if m.geom_group[g] == WALLS}
        self.sensors = site.get("range_sensors", [])
        bump = site.get("bump", {})
        self.bump_arc = bump.get("arc_rad", math.pi)
        self.max_wheel = site["robot"]["max_wheel_speed_rad_s"]
        start = site["robot"]["start"]
        self.place(start["x_m"], start["y_m"], start["heading_rad"])
        self.t = 0.0

    def place(self, x, y, heading):
        """Puts the robot at rest at (x, y, heading) and lets it settle."""
        mujoco.mj_resetData(self.model, self.data)
        q = self.data.qpos
        q[0:3] = (x, y, self.model.body_pos[self.chassis_body][2] + 0.002)
        q[3:7] = (math.cos(heading / 2), 0.0, 0.0, math.sin(heading / 2))
        mujoco.mj_forward(self.model, self.data)
        for _ in range(200):
            mujoco.mj_step(self.model, self.data)
        self.start_wheel = [self.data.qpos[a] for a in self.joint_q]

    def pose(self):
        x, y = self.data.xpos[self.chassis_body][:2]
        w, qx, qy, qz = self.data.xquat[self.chassis_body]
        return float(x), float(y), math.atan2(2 * (w * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))

    def speed_m_s(self):
        """The chassis's speed over the floor."""
        return float(np.hypot(*self.data.qvel[0:2]))

    def _contacts(self):
        """(bumper pressed, touching a wall) from the chassis's contacts."""
        x, y, th = self.pose()
        bump = touching = False
        for c in self.data.contact[: self.data.ncon]:
            pair = {c.geom1, c.geom2}
            if self.chassis_geom not in pair or not (pair & self.wall_geoms):
                continue
            bearing = math.atan2(c.pos[1] - y, c.pos[0] - x) - th
            bearing = math.atan2(math.sin(bearing), math.cos(bearing))
            if abs(bearing) <= self.bump_arc / 2:
                bump = True
            if c.dist <= 0.0:
                touching = True
        return bump, touching

    def _ranges(self):
        x, y, th = self.pose()
        z = float(self.data.xpos[self.chassis_body][2])
        groups = np.zeros(6, dtype=np.uint8)
        groups[WALLS] = 1
        out = []
        for s in self.sensors:
            m = s["mount"]
            ox = x + m["x_m"] * math.cos(th) - m["y_m"] * math.sin(th)
            oy = y + m["x_m"] * math.sin(th) + m["y_m"] * math.cos(th)
            beams = s.get("beams", 1)
            fov = s.get("fov_rad", 0.0)
            # twindrive's beam angles: a full circle is beams steps of
            # 2 pi / beams from -pi; a fan spans its field of view.
            if beams <= 1:
                first, step = 0.0, 0.0
            elif fov >= 2 * math.pi - 1e-9:
                first, step = -math.pi, 2 * math.pi / beams
            else:
                first, step = -fov / 2, fov / (beams - 1)
            lo, hi = s.get("min_range_m", 0.0), s["max_range_m"]
            # All of a sensor's beams at once: MuJoCo passes over the geoms
            # beyond the range and those no beam points at (a building's
            # map has thousands).
            angles = th + m["heading_rad"] + first + step * np.arange(beams)
            directions = np.column_stack((np.cos(angles), np.sin(angles), np.zeros(beams)))
            geomid = np.zeros(beams, dtype=np.int32)
            dist = np.zeros(beams)
            mujoco.mj_multiRay(self.model, self.data, np.array([ox, oy, z]), directions.ravel(),
                               groups, 1, -1, geomid, dist, beams, hi)
            for d in dist.tolist():
                r = hi if d < 0 or d >= hi else d
                if r < hi:
                    r = min(max(r + s.get("noise_std_m", 0.0) * self.rng.standard_normal(), lo), hi)
                if self.rng.random() < s.get("dropout_probability", 0.0):
                    r = hi
                out.append(r)
        return out

    def step(self, left, right, steps, ranges=True):
        """Drives the wheels at (left, right) rad/s (scaled down together to
        the robot's limit) for `steps` site periods; what site-sim prints
        (`ranges_m` None unless `ranges`: no sensor is due)."""
        peak = max(abs(left), abs(right))
        if peak > self.max_wheel:
            left, right = left * self.max_wheel / peak, right * self.max_wheel / peak
        self.data.ctrl[:] = (left, right)
        bump = blocked = False
        for _ in range(steps):
            for _ in range(self.substeps):
                mujoco.mj_step(self.model, self.data)
            b, touching = self._contacts()
            bump |= b
            blocked |= touching
            self.t += self.dt
        return {
            "t_s": self.t,
            "wheel_rad": [float(self.data.qpos[a] - s) for a, s in zip(self.joint_q, self.start_wheel)],
            "wheel_rad_s": [float(self.data.qvel[a]) for a in self.joint_v],
            "bump": bump,
            "blocked": blocked,
            "ranges_m": self._ranges() if ranges else None,
            "pose": list(self.pose()),
        }

    def close(self):
        """Nothing to release: the model lives in this process."""

    def braking_distance_m(self, speed_m_s):
        """How far this robot rolls on open floor from `speed_m_s` straight
        ahead once its wheels are commanded zero (m): an experiment on the
        same model, away from every wall."""
        probe = MujocoSite({**self.site, "world": {}}, 0, self.kv_nm_s, self.torque_limit_nm)
        r = sum(self.site["robot"]["true_params"][k] for k in ("left_diameter_m", "right_diameter_m")) / 4
        w = speed_m_s / r
        for _ in range(int(3.0 / probe.dt)):
            probe.step(w, w, 1)
            if abs(probe.speed_m_s() - speed_m_s) < 0.01 * max(speed_m_s, 0.01):
                break
        x0, y0, _ = probe.pose()
        for _ in range(int(3.0 / probe.dt)):
            probe.step(0.0, 0.0, 1)
            if probe.speed_m_s() < 1e-4:
                break
        x1, y1, _ = probe.pose()
        return math.hypot(x1 - x0, y1 - y0)


def parse_window(text):
    """`X0,Y0,X1,Y1` (m) as a window for `map_boxes` (an argparse type)."""
    try:
        x0, y0, x1, y1 = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X0,Y0,X1,Y1 in metres, got `{text}`") from None
    if not (x0 < x1 and y0 < y1):
        raise argparse.ArgumentTypeError(f"expected X0 < X1 and Y0 < Y1, got `{text}`")
    return x0, y0, x1, y1


def main():
    import json
    import sys
    import tomllib

    ap = argparse.ArgumentParser(description="The robot's range sensors in MuJoCo at the poses on stdin.")
    ap.add_argument("site")
    ap.add_argument("--map-window", type=parse_window)
    a = ap.parse_args()
    with open(a.site, "rb") as f:
        site = tomllib.load(f)
    sim = MujocoSite(site, base_dir=os.path.dirname(os.path.abspath(a.site)), map_window=a.map_window)
    for n, line in enumerate(sys.stdin, 1):
        if not line.strip():
            continue
        try:
            x, y, heading = (float(v) for v in line.split())
        except ValueError:
            sys.exit(f"stdin, line {n}: expected `x y heading`, got `{line.strip()}`")
        sim.place(x, y, heading)
        print(json.dumps({"pose": list(sim.pose()), "ranges_m": sim._ranges(), "geoms": sim.model.ngeom}))


if __name__ == "__main__":
    main()
