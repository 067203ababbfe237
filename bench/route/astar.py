"""A peer for twindrive's goal planner: plain 8-connected A* in Python
(heapq, octile heuristic) on the same grid of cells that keep the
clearance, written by `route_peer --write`. Prints its best time over
REPEAT runs and the length of the way it finds (cell centres, no
shortening), as `python_ms` and `python_length_m`.

Usage: astar.py DIR REPEAT
"""

import heapq
import json
import math
import sys
import time


def astar(passable, width, height, start, goal):
    sx, sy = start
    gx, gy = goal
    diag = math.sqrt(2.0)

    def h(x, y):
        dx, dy = abs(x - gx), abs(y - gy)
        return (dx + dy) + (diag - 2.0) * min(dx, dy)

    cost = {(sx, sy): 0.0}
    heap = [(h(sx, sy), 0.0, sx, sy)]
    moves = [(1, 0, 1.0), (-1, 0, 1.0), (0, 1, 1.0), (0, -1, 1.0),
             (1, 1, diag), (1, -1, diag), (-1, 1, diag), (-1, -1, diag)]
    while heap:
        _, c, x, y = heapq.heappop(heap)
        if (x, y) == (gx, gy):
            return c
        if c > cost.get((x, y), math.inf):
            continue
        for dx, dy, step in moves:
            nx, ny = x + dx, y + dy
            if 0 <= nx < width and 0 <= ny < height and passable[ny][nx]:
                nc = c + step
                if nc < cost.get((nx, ny), math.inf):
                    cost[(nx, ny)] = nc
                    heapq.heappush(heap, (nc + h(nx, ny), nc, nx, ny))
    return None


def main():
    folder, repeat = sys.argv[1], int(sys.argv[2])
    with open(f"{folder}/passable.txt") as f:
        passable = [[ch == "1" for ch in line.strip()] for line in f if line.strip()]
    with open(f"{folder}/query.json") as f:
        q = json.load(f)
    height, width = len(passable), len(passable[0])
    best, length = math.inf, None
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        cells = astar(passable, width, height, tuple(q["start"]), tuple(q["goal"]))
        best = min(best, (time.perf_counter() - t0) * 1e3)
        length = cells
    if length is None:
        sys.exit("python: no way found")
    print(f"python_ms {best:.3f}")
    print(f"python_length_m {length * q['cell_m']:.3f}")


if __name__ == "__main__":
    main()
