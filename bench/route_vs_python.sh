#!/usr/bin/env bash
# Goal planning side by side: twindrive's planner (the grid of footprint
# clearances built from the site, A*, legs shortened by line of sight)
# against plain 8-connected A* in Python (bench/route/astar.py) on the same
# 20 m x 20 m site with rooms and clutter at 5 cm cells (seed SEED), the
# Python side given the grid of passable cells ready-made. Prints each
# side's best time, the ways' lengths and the ratio.
# Usage: bench/route_vs_python.sh   (from any directory; SEED=... REPEAT=...)
#   SMOKE=1   one run each: checks that both sides still run and agree
set -euo pipefail

SMOKE=${SMOKE:-0}
SEED=${SEED:-1}
REPEAT=${REPEAT:-20}
PY_REPEAT=${PY_REPEAT:-3}
if [[ $SMOKE == 1 ]]; then
    REPEAT=1
    PY_REPEAT=1
fi

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
source bench/profile.sh

TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
build -p twindrive-mission --example route_peer
PEER=$ROOT/target/$PROFILE_DIR/examples/route_peer

"$PEER" --write "$SEED" "$TMP"
"$PEER" --run "$SEED" "$REPEAT" >"$TMP/rust.out"
python3 bench/route/astar.py "$TMP" "$PY_REPEAT" >"$TMP/python.out"

value() { awk -v k="$2" '$1 == k { print $2; found = 1 } END { if (!found) { print "no " k " in " FILENAME > "/dev/stderr"; exit 1 } }' "$1"; }
rust_ms=$(value "$TMP/rust.out" twindrive_ms)
search_ms=$(value "$TMP/rust.out" twindrive_search_ms)
rust_m=$(value "$TMP/rust.out" twindrive_length_m)
py_ms=$(value "$TMP/python.out" python_ms)
py_m=$(value "$TMP/python.out" python_length_m)
# Line-of-sight legs are never longer than the cells they replace.
awk -v r="$rust_m" -v p="$py_m" 'BEGIN { if (r > p * 1.001 + 0.1) { print "MISMATCH: twindrive " r " m against A* " p " m" > "/dev/stderr"; exit 1 } }'
echo "20 m x 20 m at 5 cm, corner to corner (seed $SEED):"
echo "  twindrive: ${rust_ms} ms (grid and way; the way alone ${search_ms} ms), ${rust_m} m"
echo "  Python A* on the ready grid: ${py_ms} ms, ${py_m} m (cell centres, not shortened)"
awk -v r="$rust_ms" -v p="$py_ms" 'BEGIN { printf "  ratio (Python / twindrive, grid included): %.1fx\n", p / r }'
