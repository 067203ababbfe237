#!/usr/bin/env bash
# Side-by-side redundancy removal: the paper's method (a full distance
# matrix, in numpy: bench/distance_matrix/prune_numpy.py) against twindrive's
# grid-hash pinch finder and its own distance-matrix reference
# (find_pinches_reference), on one wall-following path of N samples (default
# 20 000). Checks that all three find the same pinch points and keep the same
# samples, then prints the times and the ratios.
# Usage: bench/prune_vs_distance_matrix.sh   (from any directory; N=... SEED=...)
# Needs python3 and about 4 GB of free memory (the Rust reference holds the
# whole 20 000 x 20 000 matrix: 3.2 GB; numpy works in blocks of rows).
# Takes about a minute, mostly numpy.
#   SMOKE=1   2 000 samples (seconds): checks that every side still runs and agrees
#   PEERS=0   twindrive's side only (the grid hash against the Rust reference; no numpy)
set -euo pipefail

NUMPY_VERSION=2.4.6
SMOKE=${SMOKE:-0}
PEERS=${PEERS:-1}
if [[ $SMOKE == 1 ]]; then
    N=${N:-2000}
    FAST_REPEAT=${FAST_REPEAT:-2}
fi
N=${N:-20000}
SEED=${SEED:-1}
FAST_REPEAT=${FAST_REPEAT:-50}

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV=$ROOT/.venv-numpy
cd "$ROOT"
source bench/profile.sh

TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
build -p twindrive-mission --example prune_peer
PEER=$ROOT/target/$PROFILE_DIR/examples/prune_peer

echo "writing a $N-sample path (seed $SEED) ..." >&2
"$PEER" --write "$N" "$SEED" "$TMP/path.csv" "$TMP/config.json"
echo "twindrive: grid hash (best of $FAST_REPEAT) and distance-matrix reference ..." >&2
# --reference fails unless the reference finds and keeps what the grid hash does.
"$PEER" --run "$TMP/path.csv" "$TMP/config.json" "$TMP" --reference --repeat "$FAST_REPEAT" >"$TMP/rust.out"
if [[ $PEERS != 1 ]]; then
    cat "$TMP/rust.out"
    exit 0
fi

if [[ ! -x $VENV/bin/python ]]; then
    python3 -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --disable-pip-version-check "numpy==$NUMPY_VERSION" >&2
"$VENV/bin/python" bench/distance_matrix/prune_numpy.py --self-test
echo "numpy $NUMPY_VERSION distance matrix ..." >&2
"$VENV/bin/python" bench/distance_matrix/prune_numpy.py "$TMP/path.csv" "$TMP/config.json" "$TMP" >"$TMP/numpy.out"

value() { awk -v k="$2" '$1 == k { print $2; found = 1 } END { if (!found) { print "no " k " in " FILENAME > "/dev/stderr"; exit 1 } }' "$1"; }
for what in pinches kept; do
    if ! cmp -s "$TMP/${what}_fast.txt" "$TMP/${what}_numpy.txt"; then
        echo "MISMATCH: numpy and twindrive differ in $what:" >&2
        diff "$TMP/${what}_fast.txt" "$TMP/${what}_numpy.txt" | head -20 >&2
        exit 1
    fi
done

fast_find=$(value "$TMP/rust.out" fast_find_s)
fast_remove=$(value "$TMP/rust.out" fast_remove_s)
ref_find=$(value "$TMP/rust.out" reference_find_s)
ref_remove=$(value "$TMP/rust.out" reference_remove_s)
np_find=$(value "$TMP/numpy.out" numpy_find_s)
np_matrix=$(value "$TMP/numpy.out" numpy_find_distance_matrix_s)
np_remove=$(value "$TMP/numpy.out" numpy_remove_s)
np_rss=$(value "$TMP/numpy.out" numpy_peak_rss_mb)

echo "$(value "$TMP/rust.out" samples) samples: $(value "$TMP/rust.out" pinches) pinch points," \
    "$(value "$TMP/rust.out" kept) samples kept; numpy, the Rust reference and the grid hash agree"
printf '%-34s %14s %14s\n' implementation "find pinches" "remove loops"
printf '%-34s %13.4fs %13.4fs\n' "numpy $NUMPY_VERSION distance matrix" "$np_find" "$np_remove"
printf '%-34s %13.4fs %14s\n' "  of which the distances alone" "$np_matrix" ""
printf '%-34s %13.4fs %13.4fs\n' "twindrive distance-matrix reference" "$ref_find" "$ref_remove"
printf '%-34s %13.6fs %13.6fs\n' "twindrive grid hash" "$fast_find" "$fast_remove"
echo "numpy peak memory: ${np_rss} MB (the matrix in blocks of $(value "$TMP/numpy.out" numpy_block_rows) rows)"
awk -v a="$np_find" -v m="$np_matrix" -v r="$ref_find" -v f="$fast_find" \
    -v ar="$np_remove" -v rr="$ref_remove" -v fr="$fast_remove" 'BEGIN {
    printf "grid hash vs numpy:           %8.0fx (find), %8.0fx (remove), %8.0fx (numpy distances alone vs find)\n", a / f, ar / fr, m / f
    printf "grid hash vs Rust reference:  %8.0fx (find), %8.0fx (remove)\n", r / f, rr / fr
}'
