#!/usr/bin/env bash
# Scan-to-scan matching (laser odometry): twindrive's matcher (PL-ICP with
# projective association, crates/estimation/src/localize) against Open3D's
# ICP (`open3d-cpu`, point-to-point and point-to-plane) on the same pairs of
# 360-beam scans from random rooms: 1-3 cm range noise, 1 % dropouts,
# max-range readings, motions up to 0.3 m and 20 degrees, priors up to 5 cm
# and 3 degrees off (`scan_pairs --write`). Both on one thread, both from
# the same prior with the same 0.3 m correspondence distance. Prints the
# time per pair and the RMS errors against the true motion for each, and
# fails unless twindrive is at least 10x faster than each Open3D variant
# and at least as accurate (translation and heading) as the better one.
# Usage: bench/scan_match_vs_open3d.sh   (from any directory)
#   SMOKE=1   20 pairs, no ratio check
#   PEERS=0   twindrive's side only
#   PAIRS=N   pairs (default 2000)
set -euo pipefail
SMOKE=${SMOKE:-0}
PEERS=${PEERS:-1}
PAIRS=${PAIRS:-2000}
REPEAT=5
if [[ $SMOKE == 1 ]]; then
    PAIRS=20
    REPEAT=1
fi
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
source bench/profile.sh
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

value_of() { awk -v k="$1" '$1 == k { v = $2 } END { if (v == "") exit 1; print v }'; }

build -p twindrive-estimation --example scan_pairs
example_bin scan_pairs --write "$WORK/pairs.bin" --pairs "$PAIRS" --seed 1
ours=$(taskset -c 0 "$ROOT/target/$PROFILE_DIR/examples/scan_pairs" --run "$WORK/pairs.bin" --repeat "$REPEAT")
t_us=$(value_of us_per_pair <<<"$ours")
t_xy=$(value_of rmse_xy_m <<<"$ours")
t_th=$(value_of rmse_theta_rad <<<"$ours")
echo "== $PAIRS pairs of 360-beam scans, one thread"
printf '%-26s %12s %14s %16s\n' matcher "us/pair" "RMSE xy (mm)" "RMSE heading (deg)"
row() { awk -v n="$1" -v t="$2" -v xy="$3" -v th="$4" 'BEGIN { printf "%-26s %12.1f %14.2f %16.4f\n", n, t, xy * 1000, th * 57.29578 }'; }
row "twindrive (refused $(value_of refused <<<"$ours"))" "$t_us" "$t_xy" "$t_th"
if [[ $PEERS != 1 ]]; then
    exit 0
fi
PY=$(bash scripts/open3d-deps.sh)
peer=$(OMP_NUM_THREADS=1 taskset -c 0 "$PY" bench/open3d/icp_pairs.py "$WORK/pairs.bin")
status=0
best_xy=1e9
best_th=1e9
for v in point_to_point point_to_plane; do
    o_us=$(value_of "${v}_us_per_pair" <<<"$peer")
    o_xy=$(value_of "${v}_rmse_xy_m" <<<"$peer")
    o_th=$(value_of "${v}_rmse_theta_rad" <<<"$peer")
    row "open3d $v" "$o_us" "$o_xy" "$o_th"
    best_xy=$(awk -v a="$best_xy" -v b="$o_xy" 'BEGIN { print (b < a ? b : a) }')
    best_th=$(awk -v a="$best_th" -v b="$o_th" 'BEGIN { print (b < a ? b : a) }')
    ratio=$(awk -v o="$o_us" -v t="$t_us" 'BEGIN { printf "%.1f", o / t }')
    echo "twindrive is ${ratio}x faster than open3d $v"
    if [[ $SMOKE != 1 ]] && awk -v r="$ratio" 'BEGIN { exit !(r < 10) }'; then
        echo "FAIL: less than 10x faster than open3d $v" >&2
        status=1
    fi
done
if [[ $SMOKE != 1 ]] && awk -v a="$t_xy" -v b="$best_xy" -v c="$t_th" -v d="$best_th" 'BEGIN { exit !(a > b || c > d) }'; then
    echo "FAIL: less accurate than Open3D's better variant" >&2
    status=1
fi
exit $status
