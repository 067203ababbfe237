#!/usr/bin/env bash
# Side-by-side augmented EKF: filterpy's ExtendedKalmanFilter vs twindrive's
# AugmentedEkf on the same calibration-drive input (the model is described in
# bench/filterpy/run_filterpy.py). Checks that the final parameter estimates
# agree, then prints steps/s (one step = one predict + one update) and the ratio.
# Usage: bench/ekf_vs_filterpy.sh   (from any directory)
#   SMOKE=1   a few repeats only (seconds): checks that both sides still run
#   PEERS=0   twindrive's side only (no Python, no filterpy)
set -euo pipefail

FILTERPY_VERSION=1.4.5
NUMPY_VERSION=2.4.6
SCIPY_VERSION=1.17.1   # filterpy's update inverts S with scipy.linalg.inv
SMOKE=${SMOKE:-0}
PEERS=${PEERS:-1}
FILTERPY_REPEAT=${FILTERPY_REPEAT:-1}
if [[ $SMOKE == 1 ]]; then
    TWINDRIVE_REPEAT=${TWINDRIVE_REPEAT:-2}
fi
TWINDRIVE_REPEAT=${TWINDRIVE_REPEAT:-200}
RTOL=1e-6

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV=$ROOT/.venv-filterpy
cd "$ROOT"
source bench/profile.sh

TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
build -p twindrive-estimation --example ekf_throughput
example() { example_bin ekf_throughput "$@"; }

echo "writing the input ..." >&2
example --write-input "$TMP/input.csv"
echo "twindrive, repeat $TWINDRIVE_REPEAT ..." >&2
example --run "$TMP/input.csv" --repeat "$TWINDRIVE_REPEAT" >"$TMP/twindrive.out"
if [[ $PEERS != 1 ]]; then
    cat "$TMP/twindrive.out"
    exit 0
fi

if [[ ! -x $VENV/bin/python ]]; then
    python3 -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --disable-pip-version-check \
    "filterpy==$FILTERPY_VERSION" "numpy==$NUMPY_VERSION" "scipy==$SCIPY_VERSION" >&2
"$VENV/bin/python" bench/filterpy/run_filterpy.py --self-test >&2
echo "filterpy $FILTERPY_VERSION, repeat $FILTERPY_REPEAT ..." >&2
"$VENV/bin/python" bench/filterpy/run_filterpy.py --input "$TMP/input.csv" --repeat "$FILTERPY_REPEAT" >"$TMP/filterpy.out"

# "<rate> <dL> <dR> <b>" from one implementation's output
summary() {
    awk -v k="$2" '$1 == k { r = $2 } $1 == "final" { f = $2 " " $3 " " $4 }
        END { if (r == "" || f == "") { print "no result in " FILENAME > "/dev/stderr"; exit 1 }
              print r, f }' "$1"
}
fp=$(summary "$TMP/filterpy.out" filterpy_steps_per_s)
td=$(summary "$TMP/twindrive.out" steps_per_s)
read -r fp_rate fp_dl fp_dr fp_b <<<"$fp"
read -r td_rate td_dl td_dr td_b <<<"$td"

# Largest relative difference of the final parameters; fail unless all <= RTOL.
if ! maxrel=$(awk -v a="$fp_dl $fp_dr $fp_b" -v b="$td_dl $td_dr $td_b" -v t="$RTOL" 'BEGIN {
    split(a, x, " "); split(b, y, " "); m = 0; ok = 1
    for (i = 1; i <= 3; i++) {
        d = x[i] - y[i]; d = (d < 0 ? -d : d) / (y[i] < 0 ? -y[i] : y[i])
        if (!(d <= t)) ok = 0
        if (d > m) m = d
    }
    printf "%.1e", m; exit !ok }'); then
    echo "MISMATCH: final parameters differ by a relative $maxrel (limit $RTOL)" >&2
    cat "$TMP/filterpy.out" "$TMP/twindrive.out" >&2
    exit 1
fi

printf '%-18s %14s %12s %12s %12s\n' implementation steps/s dL dR b
printf '%-18s %14.1f %12.9f %12.9f %12.9f\n' "filterpy $FILTERPY_VERSION" "$fp_rate" "$fp_dl" "$fp_dr" "$fp_b"
printf '%-18s %14.1f %12.9f %12.9f %12.9f\n' twindrive "$td_rate" "$td_dl" "$td_dr" "$td_b"
echo "final parameters agree: max relative difference $maxrel (limit $RTOL)"
awk -v a="$fp_rate" -v b="$td_rate" 'BEGIN { printf "ratio twindrive/filterpy: %.1fx\n", b / a }'
