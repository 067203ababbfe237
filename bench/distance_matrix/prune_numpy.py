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
  sample strictly between (protected: first, last with keep_end, keep
  regions and windows, reversing samples when reversing is not redundant).
  Only the farthest j of each i is reported; Near wins ties.
- kinks: a maximal run of v < 0 samples; e = the sample after it (the last
  if the path ends reversing); k = the sample before the run nearest to e,
  looking back over the reversed length plus the pinch distance, not before
  the last protected sample; cut (k, e) if closer than the pinch distance.
- coverage: a sample is covered by a piece of path (segment or point) when
  its squared distance to it, computed as geometry::segment_distance2 does,
  is at most the squared coverage radius (default: the pinch distance).
- removal: one sweep. At each kept sample i: past the last new ground and
  the last protected sample (and without keep_end), if the kept path up to
  i covers every later sample, the rest goes; else the kink from i, or the
  farthest pinch from i, is cut if the kept path up to i covers every
  sample it deletes, or else the farthest cut that ends at or before the
  first sample it would not cover; a pinch that is little more than a kink
  (the path it cuts around the kink is shorter than the min loop length)
  waits for the kink. Then on from the cut's end.

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
    crit = {
        "d": d,
        "d2": d * d,
        "L": 3.0 * d if loop is None else float(loop),
        "D": float(cfg.get("min_loop_duration_s", 0.0)),
        "reversing_is_redundant": bool(cfg.get("reversing_is_redundant", True)),
        "r": d if cfg.get("coverage_radius_m") is None else float(cfg["coverage_radius_m"]),
        "keep_end": bool(cfg.get("keep_end", False)),
    }
    crit["r2"] = crit["r"] * crit["r"]
    return crit


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
        protected[0] = True
        protected[-1] |= crit["keep_end"]
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


def segment_distance2(sx, sy, px, py, qx, qy):
    """Vectorised twin of geometry::segment_distance2 (same operations)."""
    sx, sy, px, py, qx, qy = (np.asarray(v, dtype=np.float64) for v in (sx, sy, px, py, qx, qy))
    dx, dy = qx - px, qy - py
    ex, ey = sx - px, sy - py
    dot = ex * dx + ey * dy
    length2 = dx * dx + dy * dy
    with np.errstate(divide="ignore", invalid="ignore"):
        t = dot / length2
        fx, fy = ex - t * dx, ey - t * dy
        middle = fx * fx + fy * fy
    gx, gy = sx - qx, sy - qy
    return np.where(dot <= 0.0, ex * ex + ey * ey, np.where(dot >= length2, gx * gx + gy * gy, middle))


class Sweep:
    """The removal sweep over the whole path, testing coverage against every piece."""

    def __init__(self, tr, crit, block_rows, clock):
        self.tr, self.crit, self.block_rows, self.clock = tr, crit, block_rows, clock
        n = len(tr)
        self.kept = np.ones(n, dtype=bool)
        self.lo, self.hi = loop_starts(tr, crit), next_protected(tr)
        self.sx0 = np.concatenate([[tr.x[0]], tr.x[:-1]]) if n else tr.x
        self.sy0 = np.concatenate([[tr.y[0]], tr.y[:-1]]) if n else tr.y

    # -- pieces of path
    def kept_pieces(self, i):
        """Segments (a, a+1) and points a of the kept path up to i: (p, q) arrays."""
        x, y, kept = self.tr.x, self.tr.y, self.kept
        a = np.nonzero(kept[: i + 1])[0]
        seg = np.zeros(len(a), dtype=bool)
        inner = a < i
        seg[inner] = kept[a[inner] + 1]
        b = np.where(seg, a + 1, a)
        return x[a], y[a], x[b], y[b]

    def prefix_pieces(self, lo, hi, last):
        """Pieces a in lo..=hi of the whole path, segments up to `last`."""
        x, y = self.tr.x, self.tr.y
        a = np.arange(lo, hi + 1)
        b = np.where(a < last, a + 1, a)
        return x[a], y[a], x[b], y[b]

    def within(self, s, pieces):
        px, py, qx, qy = pieces
        if len(px) == 0:
            return False
        d2 = segment_distance2(self.tr.x[s], self.tr.y[s], px, py, qx, qy)
        return bool((d2 <= self.crit["r2"]).any())

    def first_uncovered(self, i, end):
        pieces = self.kept_pieces(i)
        for s in range(i + 1, end):
            if not self.within(s, pieces):
                return s
        return None

    def would_drop_m(self, i, j):
        n = len(self.tr)
        before, after = self.kept_pieces(i), self.prefix_pieces(j, n - 1, n - 1)
        flags = [s != i and s != j and not (self.within(s, before) or self.within(s, after)) for s in range(i, j + 1)]
        cum, total = self.tr.cum, 0.0
        for a in range(1, len(flags)):
            ends = int(flags[a - 1]) + int(flags[a])
            if ends:
                total += 0.5 * ends * (cum[i + a] - cum[i + a - 1])
        return total

    def last_new_sample(self):
        """The last sample farther than r from the path ending 2 r (along the path) before it."""
        cum, r = self.tr.cum.tolist(), self.crit["r"]
        n = len(self.tr)
        upto = n
        for s in range(n - 1, -1, -1):
            reach = cum[s] - 2.0 * r
            if reach < 0.0:
                return s
            upto = min(upto, s)
            while upto > 0 and cum[upto] > reach:
                upto -= 1
            if not self.within(s, self.prefix_pieces(0, upto, upto)):
                return s
        return 0

    # -- the finder, one sample at a time (one row of the matrix)
    def farthest(self, i, hi):
        tr, crit = self.tr, self.crit
        n = len(tr)
        lo = int(self.lo[i])
        hi = min(hi, n - 1)
        if i + 2 >= n or lo > hi:
            return None
        x, y = tr.x, tr.y
        start = time.perf_counter()
        J = np.arange(lo, hi + 1)
        dx, dy = x[i] - x[J], y[i] - y[J]
        near = J[dx * dx + dy * dy < crit["d2"]]
        near_j = int(near.max()) if len(near) else -1
        middle = time.perf_counter()
        C = J[(J >= i + 3) & (J > near_j)]
        cross_j = -1
        if len(C):
            a = i + 1
            box = boxes_overlap(x[i], y[i], x[a], y[a], self.sx0[C], self.sy0[C], x[C], y[C])
            C = C[box]
            meet = segments_meet(x[i], y[i], x[a], y[a], self.sx0[C], self.sy0[C], x[C], y[C])
            if meet.any():
                cross_j = int(C[meet].max())
        self.clock["distance_s"] += middle - start
        self.clock["crossing_s"] += time.perf_counter() - middle
        if cross_j > near_j:
            return cross_j, "crossing"
        if near_j >= 0:
            return near_j, "loop"
        return None

    def run(self):
        tr, crit = self.tr, self.crit
        n = len(tr)
        if n < 3:
            return list(range(n))
        kink_end = [0] * n
        if crit["reversing_is_redundant"]:
            for k, e in kinks(tr, crit):
                kink_end[k] = max(kink_end[k], e)
        next_kink = [n] * n
        for k in range(n - 2, -1, -1):
            next_kink[k] = k + 1 if kink_end[k + 1] else next_kink[k + 1]
        cum = tr.cum.tolist()

        def candidate(i, hi):
            if kink_end[i] and kink_end[i] <= hi:
                return kink_end[i], "reversal"
            return self.farthest(i, hi)

        def swallows_a_kink(i, j):
            k = next_kink[i]
            return k < j and kink_end[k] <= j and (cum[k] - cum[i]) + (cum[j] - cum[kink_end[k]]) < crit["L"]

        truncate_from = None
        if not crit["keep_end"]:
            last_protected = int(np.nonzero(tr.protected)[0].max())
            truncate_from = max(self.last_new_sample(), last_protected)
        i = 0
        while i + 1 < n:
            if truncate_from is not None and i >= truncate_from and self.first_uncovered(i, n) is None:
                self.kept[i + 1 :] = False
                break
            hi = int(self.hi[i])
            chosen = None
            c = candidate(i, hi)
            if c is not None:
                u = self.first_uncovered(i, c[0])
                if u is None:
                    chosen = c
                else:
                    chosen = candidate(i, min(hi, u))
            if chosen is not None and chosen[1] != "reversal" and swallows_a_kink(i, chosen[0]):
                i += 1
            elif chosen is not None:
                self.kept[i + 1 : chosen[0]] = False
                i = chosen[0]
            else:
                i += 1
        return np.nonzero(self.kept)[0].tolist()


def remove_redundancy(tr, crit, block_rows, clock):
    """Indices of the samples kept (`Sweep`)."""
    return Sweep(tr, crit, block_rows, clock).run()


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
    # Coverage: a segment, its ends, a point.
    d2 = segment_distance2(np.array([1.0, -3.0, 5.0, 1.0]), np.array([3.0, 4.0, 4.0, 0.0]), 0.0, 0.0, 2.0, 0.0)
    assert d2.tolist() == [9.0, 25.0, 25.0, 0.0], d2
    assert segment_distance2(3.0, 4.0, 0.0, 0.0, 0.0, 0.0) == 25.0
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
