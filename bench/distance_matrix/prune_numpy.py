"""The paper's redundancy removal with a full distance matrix, in numpy.

The Python peer of `cargo run -p twindrive-mission --example prune_peer`
(bench/prune_vs_distance_matrix.sh runs both). Section 5 of the paper: "A
matrix of distances between the coordinates on the redundant path is used
to find pinch points ... These pinch points are used to delete any kinks or
loops in the robot path". twindrive's definitions, spelled out with the same
floating-point operations so that both sides agree to the bit:

- a pinch (i, j), j >= i + 2: squared distance (x_i - x_j)^2 + (y_i - y_j)^2
  below the squared pinch distance, or (j >= i + 3) segments (i, i+1) and
  (j-1, j) meet (closed segments, bounding boxes first, then orientations);
  cum[j] - cum[i] >= min loop length (cum: running sum of
  sqrt(dx^2 + dy^2)), t[j] - t[i] >= min loop duration, and no protected
  sample strictly between (protected: first, last, keep regions and windows,
  reversing samples when reversing is not redundant). Only the farthest j of
  each i is reported; Near wins ties.
- kinks: a maximal run of v < 0 samples; e = the sample after it (the last
  if the path ends reversing); k = the sample before the run nearest to e,
  looking back over the reversed length plus the pinch distance, not before
  the last protected sample; cut (k, e) if closer than the pinch distance.
- removal: rounds of (kinks, then pinches), each cut outermost first
  (earliest start, farthest end, go on from there), until nothing changes.

The matrix is computed in blocks of rows (all columns; 64 rows was the
fastest here): the same n x n distances, in a bounded working set (the
whole 20 000 x 20 000 matrix at once needs several GB with numpy's
temporaries, and is slower).

Prints `key value` lines; writes pinches_numpy.txt (`i j kind`) and
kept_numpy.txt. `--self-test` checks the predicates on small cases.
"""

import argparse
import csv
import json
import math
import resource
import sys
import time

import numpy as np

NEAR, CROSSING = "near", "crossing"


class Track:
    """The samples still in play, as flat arrays."""

    def __init__(self, x, y, t, reversing, protected, index):
        self.x, self.y, self.t = x, y, t
        self.reversing, self.protected, self.index = reversing, protected, index
        self.cum = cumulative_length(x, y)

    def __len__(self):
        return len(self.x)

    def without(self, cuts):
        keep = np.ones(len(self), dtype=bool)
        for i, j, _ in cuts:
            keep[i + 1 : j] = False
        return Track(
            self.x[keep], self.y[keep], self.t[keep],
            self.reversing[keep], self.protected[keep], self.index[keep],
        )


def cumulative_length(x, y):
    if len(x) == 0:
        return np.zeros(0)
    dx, dy = np.diff(x), np.diff(y)
    # add.accumulate sums in order, like the Rust running sum.
    return np.concatenate([[0.0], np.add.accumulate(np.sqrt(dx * dx + dy * dy))])


def criteria(cfg):
    d = float(cfg["pinch_distance_m"])
    loop = cfg.get("min_loop_length_m")
    return {
        "d": d,
        "d2": d * d,
        "L": 3.0 * d if loop is None else float(loop),
        "D": float(cfg.get("min_loop_duration_s", 0.0)),
        "reversing_is_redundant": bool(cfg.get("reversing_is_redundant", True)),
    }


def keeps(cfg, x, y, t):
    keep = np.zeros(len(x), dtype=bool)
    for r in cfg.get("keep_regions", []):
        if r["kind"] == "circle":
            dx, dy = x - r["x_m"], y - r["y_m"]
            keep |= dx * dx + dy * dy <= r["radius_m"] * r["radius_m"]
        else:
            keep |= (r["min_x_m"] <= x) & (x <= r["max_x_m"]) & (r["min_y_m"] <= y) & (y <= r["max_y_m"])
    for w in cfg.get("keep_windows", []):
        keep |= (w["start_s"] <= t) & (t <= w["end_s"])
    return keep


def track_from(samples, cfg, crit):
    t, x, y, v = (np.array(c, dtype=np.float64) for c in samples)
    n = len(x)
    reversing = v < 0.0
    protected = keeps(cfg, x, y, t)
    if not crit["reversing_is_redundant"]:
        protected |= reversing
    if n:
        protected[0] = protected[-1] = True
    return Track(x, y, t, reversing, protected, np.arange(n))


def next_protected(tr):
    n = len(tr)
    out = np.zeros(n, dtype=np.int64)
    after = max(n, 1) - 1
    for k in range(n - 1, -1, -1):
        out[k] = after
        if tr.protected[k]:
            after = k
    return out


def loop_starts(tr, crit):
    """For each i the first j >= i + 2 with a path from i long and slow
    enough (both only grow with j: one sweep, as in the Rust finder)."""
    n = len(tr)
    cum, t = tr.cum.tolist(), tr.t.tolist()
    lo = np.empty(n, dtype=np.int64)
    j = 0
    for i in range(n):
        j = max(j, i + 2)
        while j < n and not (cum[j] - cum[i] >= crit["L"] and t[j] - t[i] >= crit["D"]):
            j += 1
        lo[i] = j
    return lo


def orient(ax, ay, bx, by, cx, cy):
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


def in_box(ax, ay, bx, by, px, py):
    return (
        (np.minimum(ax, bx) <= px) & (px <= np.maximum(ax, bx))
        & (np.minimum(ay, by) <= py) & (py <= np.maximum(ay, by))
    )


def segments_meet(p1x, p1y, p2x, p2y, p3x, p3y, p4x, p4y):
    """Vectorised twin of geometry::segments_meet (bounding boxes checked by the caller)."""
    d1 = orient(p3x, p3y, p4x, p4y, p1x, p1y)
    d2 = orient(p3x, p3y, p4x, p4y, p2x, p2y)
    d3 = orient(p1x, p1y, p2x, p2y, p3x, p3y)
    d4 = orient(p1x, p1y, p2x, p2y, p4x, p4y)
    proper = (((d1 > 0) & (d2 < 0)) | ((d1 < 0) & (d2 > 0))) & (((d3 > 0) & (d4 < 0)) | ((d3 < 0) & (d4 > 0)))
    touch = (
        ((d1 == 0) & in_box(p3x, p3y, p4x, p4y, p1x, p1y))
        | ((d2 == 0) & in_box(p3x, p3y, p4x, p4y, p2x, p2y))
        | ((d3 == 0) & in_box(p1x, p1y, p2x, p2y, p3x, p3y))
        | ((d4 == 0) & in_box(p1x, p1y, p2x, p2y, p4x, p4y))
    )
    return proper | touch


def boxes_overlap(ax0, ay0, ax1, ay1, bx0, by0, bx1, by1):
    return (
        (np.maximum(ax0, ax1) >= np.minimum(bx0, bx1)) & (np.maximum(bx0, bx1) >= np.minimum(ax0, ax1))
        & (np.maximum(ay0, ay1) >= np.minimum(by0, by1)) & (np.maximum(by0, by1) >= np.minimum(ay0, ay1))
    )


def farthest_pinches(tr, crit, block_rows, clock):
    """For each i the farthest pinching j: [(i, j, kind)]. `clock` gathers
    the seconds spent on the distance matrix and on the crossing test."""
    n = len(tr)
    out = []
    if n < 3:
        return out
    x, y = tr.x, tr.y
    lo, hi = loop_starts(tr, crit), next_protected(tr)
    J = np.arange(n)[None, :]
    # Segment (J-1, J) for each column J (column 0 is never a candidate).
    sx0, sy0 = np.concatenate([[x[0]], x[:-1]]), np.concatenate([[y[0]], y[:-1]])
    for i0 in range(0, n, block_rows):
        i1 = min(n, i0 + block_rows)
        rows = np.arange(i0, i1)
        I = rows[:, None]
        start = time.perf_counter()
        dx = x[i0:i1, None] - x[None, :]
        dy = y[i0:i1, None] - y[None, :]
        d2 = dx * dx + dy * dy
        del dx, dy
        valid = (J >= lo[i0:i1, None]) & (J <= hi[i0:i1, None])
        near_j = np.where(valid & (d2 < crit["d2"]), J, -1).max(axis=1)
        del d2
        middle = time.perf_counter()
        # Crossings beyond the nearest pinch only.
        a = np.minimum(rows + 1, n - 1)
        cand = valid & (J >= I + 3) & (J > near_j[:, None])
        cand &= boxes_overlap(
            x[i0:i1, None], y[i0:i1, None], x[a][:, None], y[a][:, None],
            sx0[None, :], sy0[None, :], x[None, :], y[None, :],
        )
        del valid
        r, c = np.nonzero(cand)
        del cand
        meet = segments_meet(
            x[rows[r]], y[rows[r]], x[a[r]], y[a[r]], sx0[c], sy0[c], x[c], y[c]
        )
        cross_j = np.full(i1 - i0, -1)
        np.maximum.at(cross_j, r[meet], c[meet])
        clock["distance_s"] += middle - start
        clock["crossing_s"] += time.perf_counter() - middle
        for k in range(i1 - i0):
            if cross_j[k] > near_j[k]:
                out.append((i0 + k, int(cross_j[k]), CROSSING))
            elif near_j[k] >= 0:
                out.append((i0 + k, int(near_j[k]), NEAR))
    return out


def kinks(tr, crit):
    n = len(tr)
    out = []
    if n < 3:
        return out
    x, y, cum, rev = tr.x.tolist(), tr.y.tolist(), tr.cum.tolist(), tr.reversing.tolist()
    last_protected, last = [0] * n, 0
    for k in range(n):
        if tr.protected[k]:
            last = k
        last_protected[k] = last
    r = 0
    while r < n:
        if not rev[r]:
            r += 1
            continue
        r0 = r
        while r < n and rev[r]:
            r += 1
        e = min(r, n - 1)
        first_allowed = last_protected[e - 1]
        if r0 == 0 or first_allowed >= r0:
            continue
        reach = cum[e] - cum[r0] + crit["d"]
        best = None
        for k in range(r0 - 1, first_allowed - 1, -1):
            if cum[r0] - cum[k] > reach:
                break
            dx, dy = x[k] - x[e], y[k] - y[e]
            d2 = dx * dx + dy * dy
            if best is None or d2 < best[0]:
                best = (d2, k)
        if best is not None and best[0] < crit["d2"] and e >= best[1] + 2:
            out.append((best[1], e))
    return out


def outermost(candidates):
    candidates.sort(key=lambda c: (c[0], -c[1]))
    cuts, start = [], 0
    for c in candidates:
        if c[0] >= start:
            start = c[1]
            cuts.append(c)
    return cuts


def remove_redundancy(tr, crit, block_rows, clock):
    """Indices of the samples kept; every round searches the whole path."""
    kinks_stale, pinches_stale = crit["reversing_is_redundant"], True
    while kinks_stale or pinches_stale:
        if kinks_stale:
            kinks_stale = False
            cuts = outermost([(k, e, "reversal") for k, e in kinks(tr, crit)])
            if cuts:
                tr = tr.without(cuts)
                pinches_stale = True
        if pinches_stale:
            pinches_stale = False
            cuts = outermost(farthest_pinches(tr, crit, block_rows, clock))
            if cuts:
                tr = tr.without(cuts)
                pinches_stale = True
                kinks_stale = crit["reversing_is_redundant"]
    return tr.index.tolist()


def read_path(path):
    """Columns t_s, x_m, y_m, v_m_s of the CSV."""
    cols = ([], [], [], [])
    with open(path, newline="") as f:
        rows = csv.reader(f)
        next(rows)
        for row in rows:
            for c, k in zip(cols, (0, 1, 2, 4)):
                c.append(float(row[k]))
    return cols


def self_test():
    def meets(a, b, c, d):
        p = [np.array([v]) for v in (*a, *b, *c, *d)]
        return bool(boxes_overlap(*p) & segments_meet(*p))

    assert meets((0, 0), (2, 2), (0, 2), (2, 0))
    assert meets((0, 0), (2, 0), (1, 0), (1, 5))
    assert meets((0, 0), (2, 0), (1, 0), (3, 0))
    assert not meets((0, 0), (1, 0), (2, 0), (3, 0))
    assert not meets((0, 0), (2, 0), (0, 1), (2, 1))
    assert not meets((0, 0), (1, 1), (3, 0), (2, 1))
    assert meets((1, 1), (1, 1), (0, 0), (2, 2))
    rng = np.random.default_rng(1)
    x, y = rng.normal(size=1000), rng.normal(size=1000)
    total, cum = 0.0, [0.0]
    for k in range(1, 1000):
        total += math.sqrt((x[k] - x[k - 1]) ** 2 + (y[k] - y[k - 1]) ** 2)
        cum.append(total)
    assert cumulative_length(x, y).tolist() == cum, "running sum differs"
    print("self-test passed", file=sys.stderr)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("path", nargs="?")
    ap.add_argument("config", nargs="?")
    ap.add_argument("out_dir", nargs="?")
    ap.add_argument("--block-rows", type=int, default=64)
    ap.add_argument("--self-test", action="store_true")
    args = ap.parse_args()
    if args.self_test:
        self_test()
        return
    if not (args.path and args.config and args.out_dir):
        ap.error("PATH CONFIG OUT_DIR needed")
    with open(args.config) as f:
        cfg = json.load(f)
    crit = criteria(cfg)
    samples = read_path(args.path)
    track = track_from(samples, cfg, crit)

    clock = {"distance_s": 0.0, "crossing_s": 0.0}
    start = time.perf_counter()
    pinches = farthest_pinches(track, crit, args.block_rows, clock)
    find_s = time.perf_counter() - start
    find_clock = dict(clock)

    clock = {"distance_s": 0.0, "crossing_s": 0.0}
    start = time.perf_counter()
    kept = remove_redundancy(track, crit, args.block_rows, clock)
    remove_s = time.perf_counter() - start

    with open(f"{args.out_dir}/pinches_numpy.txt", "w") as f:
        f.writelines(f"{i} {j} {kind}\n" for i, j, kind in pinches)
    with open(f"{args.out_dir}/kept_numpy.txt", "w") as f:
        f.writelines(f"{k}\n" for k in kept)
    print(f"samples {len(track)}")
    print(f"pinches {len(pinches)}")
    print(f"kept {len(kept)}")
    print(f"numpy_find_s {find_s:.6e}")
    print(f"numpy_find_distance_matrix_s {find_clock['distance_s']:.6e}")
    print(f"numpy_find_crossings_s {find_clock['crossing_s']:.6e}")
    print(f"numpy_remove_s {remove_s:.6e}")
    print(f"numpy_block_rows {args.block_rows}")
    print(f"numpy_peak_rss_mb {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f}")


if __name__ == "__main__":
    main()
