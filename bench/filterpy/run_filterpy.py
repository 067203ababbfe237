"""filterpy's ExtendedKalmanFilter on twindrive's augmented EKF model.

The Python peer of `cargo run -p twindrive-estimation --example ekf_throughput`
(bench/ekf_vs_filterpy.sh runs both). Input CSV `left_rad,right_rad,x,y,theta`:
wheel rotations since the previous row and the measured pose; the first row
only initialises. One step = one predict + one update.

Model (REP-103), state [x, y, theta, dL, dR, b]:
- predict with wheel rotations (l, r): sL = dL l/2, sR = dR r/2,
  ds = (sL + sR)/2, a = (sR - sL)/(2b), chord = ds sin(a)/a,
  x += chord cos(theta + a), y += chord sin(theta + a), theta += 2a;
  F = df/dstate, G = df/d[l, r] analytic; Q = G diag(qL, qR) G^T with
  q = 1e-6 |phi| + 1e-9 rad^2 (no other process noise).
- update with z = [x, y, theta], H = [I3 0], R = diag(1e-6, 1e-6, 4e-6),
  heading innovation wrapped to (-pi, pi]; filterpy's own update (Joseph
  form in filterpy 1.4.5 and 2.0.0); no gating.
- x0 = first pose and (0.066, 0.066, 0.26);
  P0 = diag(1e-6, 1e-6, 4e-6, 0.0066^2, 0.0066^2, 0.026^2).

filterpy idiom: subclass ExtendedKalmanFilter and override predict_x(u)
(u = (l, r)); it sets F and Q for the step, which filterpy's predict() then
uses for P = F P F^T + Q.

Prints exactly `filterpy_steps_per_s <v>` and `final <dL> <dR> <b>`; only
the filtering loop is timed. `--self-test` checks F and G against central
differences and one filterpy step against the dense Joseph-form formulas.
"""

import argparse
import csv
import inspect
import math
import sys
import time

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

NOMINAL = (0.066, 0.066, 0.26)
P0 = np.diag([1e-6, 1e-6, 4e-6] + [(0.1 * p) ** 2 for p in NOMINAL])
R = np.diag([1e-6, 1e-6, 4e-6])
H = np.hstack([np.eye(3), np.zeros((3, 3))])
WHEEL_RAD2_PER_RAD, WHEEL_FLOOR_RAD2 = 1e-6, 1e-9


def sinc(a):
    if abs(a) < 1e-3:
        a2 = a * a
        return 1.0 - a2 / 6.0 * (1.0 - a2 / 20.0)
    return math.sin(a) / a


def sinc_derivative(a):
    if abs(a) < 1e-3:
        a2 = a * a
        return -a / 3.0 * (1.0 - a2 / 10.0 * (1.0 - a2 / 28.0))
    return (a * math.cos(a) - math.sin(a)) / (a * a)


def step(s, l, r):
    """Arc step of state s (6 floats) -> (next state as a list, F, G)."""
    x, y, th, dl, dr, b = s
    sl, sr = 0.5 * dl * l, 0.5 * dr * r
    ds, a = 0.5 * (sl + sr), 0.5 * (sr - sl) / b
    sc, dsc = sinc(a), sinc_derivative(a)
    chord = ds * sc
    c, sn = math.cos(th + a), math.sin(th + a)
    nxt = [x + chord * c, y + chord * sn, th + 2.0 * a, dl, dr, b]

    def column(dds, da):  # partials of (x', y', theta') given d ds and d a
        dchord = dds * sc + ds * dsc * da
        return (dchord * c - chord * sn * da, dchord * sn + chord * c * da, 2.0 * da)

    F = np.eye(6)
    F[0, 2], F[1, 2] = -chord * sn, chord * c
    F[:3, 3] = column(0.25 * l, -0.25 * l / b)
    F[:3, 4] = column(0.25 * r, 0.25 * r / b)
    F[:3, 5] = column(0.0, -a / b)
    G = np.zeros((6, 2))
    G[:3, 0] = column(0.25 * dl, -0.25 * dl / b)
    G[:3, 1] = column(0.25 * dr, 0.25 * dr / b)
    return nxt, F, G


def wrap_angle(a):
    """To (-pi, pi], as twindrive_kinematics::wrap_angle."""
    if -math.pi < a <= math.pi:
        return a
    w = a % math.tau
    return w - math.tau if w > math.pi else w


def residual(z, hx):
    y = z - hx
    y[2, 0] = wrap_angle(y[2, 0])
    return y


def h_jacobian(x):
    return H


def hx(x):
    return x[:3]


class WheelEKF(ExtendedKalmanFilter):
    def predict_x(self, u=0):
        l, r = u
        nxt, self.F, G = step(self.x[:, 0].tolist(), l, r)
        q = np.array([WHEEL_RAD2_PER_RAD * abs(l) + WHEEL_FLOOR_RAD2,
                      WHEEL_RAD2_PER_RAD * abs(r) + WHEEL_FLOOR_RAD2])
        self.Q = (G * q) @ G.T  # G diag(q) G^T
        self.x = np.array(nxt).reshape(6, 1)


def make_filter(first):
    ekf = WheelEKF(dim_x=6, dim_z=3)
    ekf.x = np.array([first[2], first[3], first[4], *NOMINAL]).reshape(6, 1)
    ekf.P = P0.copy()
    ekf.R = R.copy()
    return ekf


def read_rows(path):
    with open(path, newline="") as f:
        reader = csv.reader(f)
        assert next(reader) == ["left_rad", "right_rad", "x", "y", "theta"]
        return [tuple(float(v) for v in row) for row in reader]


def run(rows, repeat):
    # Measurements as column vectors up front: filterpy wants z like hx(x).
    steps = [((l, r), np.array([[x], [y], [th]])) for l, r, x, y, th in rows[1:]]
    t0 = time.perf_counter()
    for _ in range(repeat):
        ekf = make_filter(rows[0])
        for u, z in steps:
            ekf.predict(u)
            ekf.update(z, h_jacobian, hx, residual=residual)
    elapsed = time.perf_counter() - t0
    return repeat * len(steps) / elapsed, ekf


def self_test():
    rng = np.random.default_rng(7)
    h = 1e-6
    for case in range(3000):
        s = np.concatenate([rng.uniform(-5, 5, 2), rng.uniform(-4, 4, 1),
                            rng.uniform(0.03, 0.3, 2), rng.uniform(0.1, 0.6, 1)])
        dl, dr, b = s[3:]
        kind = case % 5
        if kind == 0:  # straight line
            w = rng.uniform(-8, 8)
            l, r = w, w * dl / dr
        elif kind == 1:  # spin in place
            w = rng.uniform(-8, 8)
            l, r = w, -w * dl / dr
        elif kind == 2:  # tiny steps
            l, r = rng.uniform(-1e-4, 1e-4, 2)
        elif kind == 3:  # half turn at the series switch, long travel
            a = (1e-3 - 1e-9, 1e-3 + 1e-9, -1e-3 + 1e-9)[case % 3]
            travel = rng.uniform(0.2, 0.6)
            l, r = 2 * (travel - a * b) / dl, 2 * (travel + a * b) / dr
        else:
            l, r = rng.uniform(-3, 3, 2)
        _, F, G = step(s, l, r)
        Fn = np.empty((6, 6))
        for j in range(6):
            e = np.zeros(6)
            e[j] = h
            Fn[:, j] = (np.array(step(s + e, l, r)[0]) - np.array(step(s - e, l, r)[0])) / (2 * h)
        Gn = np.column_stack([
            (np.array(step(s, l + h, r)[0]) - np.array(step(s, l - h, r)[0])) / (2 * h),
            (np.array(step(s, l, r + h)[0]) - np.array(step(s, l, r - h)[0])) / (2 * h),
        ])
        for name, an, nu in (("F", F, Fn), ("G", G, Gn)):
            bad = np.abs(an - nu) >= 1e-6 * np.abs(nu) + 1e-9
            assert not bad.any(), f"{name} case {case} s={s} l={l} r={r}\n{an}\n{nu}"

    assert wrap_angle(math.pi) == math.pi and wrap_angle(-math.pi) == math.pi
    assert abs(wrap_angle(3 * math.pi / 2) + math.pi / 2) < 1e-15

    # One filterpy predict + update against the dense textbook formulas.
    first = (0.0, 0.0, 1.0, 2.0, 3.1)
    ekf = make_filter(first)
    u, z = (0.4, 0.7), np.array([[1.01], [2.02], [-3.1]])
    nxt, F, G = step(ekf.x[:, 0], *u)
    q = np.diag([WHEEL_RAD2_PER_RAD * abs(v) + WHEEL_FLOOR_RAD2 for v in u])
    P = F @ P0 @ F.T + G @ q @ G.T
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    nu = z - np.array(nxt[:3]).reshape(3, 1)
    nu[2, 0] = wrap_angle(nu[2, 0])
    assert abs(nu[2, 0]) < 0.1, "heading innovation crosses the cut"
    x_post = np.array(nxt).reshape(6, 1) + K @ nu
    A = np.eye(6) - K @ H
    P_post = A @ P @ A.T + K @ R @ K.T
    ekf.predict(u)
    ekf.update(z, h_jacobian, hx, residual=residual)
    assert np.allclose(ekf.x, x_post, rtol=1e-12, atol=1e-15)
    assert np.allclose(ekf.P, P_post, rtol=1e-9, atol=1e-18)
    # With the optimal K, Joseph and (I - KH)P agree to rounding: read the source.
    src = inspect.getsource(ExtendedKalmanFilter.update).replace(" ", "")
    assert "dot(I_KH,self.P).dot(I_KH.T)+dot(self.K,R).dot(self.K.T)" in src, \
        "filterpy's EKF update is no longer the Joseph form"
    print("self-test passed: F, G vs central differences (3000 cases), "
          "wrap, one filterpy step vs dense EKF, Joseph form in filterpy's update")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--input", help="CSV from ekf_throughput --write-input")
    ap.add_argument("--repeat", type=int, default=1, help="passes over the input")
    ap.add_argument("--self-test", action="store_true", help="check Jacobians and update, then exit")
    args = ap.parse_args()
    if args.self_test:
        self_test()
        return
    if not args.input:
        ap.error("--input is required")
    rate, ekf = run(read_rows(args.input), args.repeat)
    print(f"filterpy_steps_per_s {rate:.1f}")
    print("final {!r} {!r} {!r}".format(*(float(v) for v in ekf.x[3:, 0])))


if __name__ == "__main__":
    sys.exit(main())
