"""Open3D's ICP on the pairs `scan_pairs --write` made: the peer of
bench/scan_match_vs_open3d.sh.

Each scan becomes 3D points (z = 0) from its returns, read exactly as
twindrive reads them (a range outside (range_min, range_max) is no return).
The current scan (source) is registered to the reference scan (target)
from the same prior, with the same 0.3 m correspondence distance, by
`registration_icp` point-to-point and point-to-plane. A flat cloud's PCA
normals point along z, so the target's normals for point-to-plane are set
from the 2D neighbourhood instead (the 10 nearest points in the plane);
that and building the clouds are left out of the time: only the
registration call is timed. One thread (OMP_NUM_THREADS=1, set by the
script). Prints, per variant, `<variant>_us_per_pair`,
`<variant>_rmse_xy_m`, `<variant>_rmse_theta_rad`.

Usage: python icp_pairs.py PAIRS_FILE
"""

import math
import struct
import sys
import time

import numpy as np
import open3d as o3d


def read_pairs(path):
    data = open(path, "rb").read()
    at = 0

    def take(fmt):
        nonlocal at
        size = struct.calcsize(fmt)
        if at + size > len(data):
            sys.exit(f"{path}: ends at byte {len(data)}, inside a record")
        values = struct.unpack_from(fmt, data, at)
        at += size
        return values

    def scan():
        angle_min, inc, rmin, rmax = take("<4d")
        (beams,) = take("<I")
        nonlocal at
        ranges = np.frombuffer(data, dtype="<f4", count=beams, offset=at).astype(np.float64)
        at += 4 * beams
        bearings = angle_min + inc * np.arange(beams)
        ok = np.isfinite(ranges) & (ranges > rmin) & (ranges < rmax)
        r, b = ranges[ok], bearings[ok]
        return np.stack([r * np.cos(b), r * np.sin(b), np.zeros_like(r)], axis=1)

    (count,) = take("<I")
    pairs = []
    for _ in range(count):
        truth = take("<3d")
        prior = take("<3d")
        pairs.append((truth, prior, scan(), scan()))
    return pairs


def matrix(pose):
    x, y, t = pose
    c, s = math.cos(t), math.sin(t)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:2, 3] = [x, y]
    return m


def planar_normals(cloud, points):
    tree = o3d.geometry.KDTreeFlann(cloud)
    normals = np.zeros_like(points)
    for i, p in enumerate(points):
        _, idx, _ = tree.search_knn_vector_3d(p, 10)
        q = points[np.asarray(idx)][:, :2]
        q = q - q.mean(axis=0)
        _, vecs = np.linalg.eigh(q.T @ q)
        normals[i, :2] = vecs[:, 0]
    return normals


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: icp_pairs.py PAIRS_FILE")
    pairs = read_pairs(sys.argv[1])
    criteria = o3d.pipelines.registration.ICPConvergenceCriteria(
        relative_fitness=1e-6, relative_rmse=1e-6, max_iteration=50
    )
    variants = {
        "point_to_point": o3d.pipelines.registration.TransformationEstimationPointToPoint(),
        "point_to_plane": o3d.pipelines.registration.TransformationEstimationPointToPlane(),
    }
    for name, estimation in variants.items():
        seconds, sxy, sth = 0.0, 0.0, 0.0
        for truth, prior, ref, cur in pairs:
            target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(ref))
            source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cur))
            if name == "point_to_plane":
                target.normals = o3d.utility.Vector3dVector(planar_normals(target, ref))
            init = matrix(prior)
            start = time.perf_counter()
            result = o3d.pipelines.registration.registration_icp(
                source, target, 0.3, init, estimation, criteria
            )
            seconds += time.perf_counter() - start
            t = np.asarray(result.transformation)
            x, y, th = t[0, 3], t[1, 3], math.atan2(t[1, 0], t[0, 0])
            sxy += (x - truth[0]) ** 2 + (y - truth[1]) ** 2
            sth += math.remainder(th - truth[2], math.tau) ** 2
        n = max(len(pairs), 1)
        print(f"{name}_us_per_pair {seconds * 1e6 / n:.2f}")
        print(f"{name}_rmse_xy_m {math.sqrt(sxy / n):.6f}")
        print(f"{name}_rmse_theta_rad {math.sqrt(sth / n):.6f}")


if __name__ == "__main__":
    main()
