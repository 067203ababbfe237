#!/usr/bin/env bash
# `twindrive calibrate` with no pose reference, end to end on one core: the
# self-calibration drive's log (scenarios/self_calibration_drive.toml,
# 120 s of driving, a 360-beam lidar at 10 Hz, encoders at 50 Hz, a gyro at
# 100 Hz) read, laser odometry, Censi's closed form, the maximum-likelihood
# fit and every output written. Three runs; fails above the 2 s target.
# Usage: bench/self_calibrate.sh   (from any directory)
#   SMOKE=1   the dev build, no target checked
set -euo pipefail
SMOKE=${SMOKE:-0}
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
source bench/profile.sh
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

build -p twindrive --bin twindrive
bin=./target/$PROFILE_DIR/twindrive
$bin simulate scenarios/self_calibration_drive.toml --out "$WORK/sim" > /dev/null
runs=()
for i in 1 2 3; do
    start=$EPOCHREALTIME
    taskset -c 0 $bin calibrate "$WORK/sim" --out "$WORK/out/calib.json" > /dev/null
    end=$EPOCHREALTIME
    runs+=("$(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.3f", b - a }')")
done
echo "drive_s 120"
echo "self_calibrate_wall_clock_s ${runs[*]}"
if [[ $SMOKE != 1 ]]; then
    best=$(printf '%s\n' "${runs[@]}" | sort -n | head -1)
    if awk -v t="$best" 'BEGIN { exit !(t >= 2) }'; then
        echo "FAIL: self-calibration took ${best} s, the target is under 2 s" >&2
        exit 1
    fi
fi
