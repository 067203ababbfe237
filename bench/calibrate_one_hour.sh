#!/usr/bin/env bash
# End-to-end `twindrive calibrate` on a one-hour log (encoders at 50 Hz,
# tracker at 120 Hz, generic CSVs), CSV parsing and all outputs included.
# Usage: bench/calibrate_one_hour.sh   (from any directory)
#   SMOKE=1   a one-minute log instead (seconds): checks that it still runs
set -euo pipefail
SMOKE=${SMOKE:-0}
DURATION_S=3600
if [[ $SMOKE == 1 ]]; then
    DURATION_S=60
fi
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
source bench/profile.sh
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

build -p twindrive --bin twindrive
build -p twindrive-estimation --example one_hour_log
example_bin one_hour_log "$WORK/log" "$DURATION_S" >&2
runs=()
for i in 1 2 3; do
    start=$EPOCHREALTIME
    ./target/$PROFILE_DIR/twindrive calibrate --encoders "$WORK/log/encoders.csv" --poses "$WORK/log/poses.csv" \
        --ticks-per-rev 512 --initial 0.066,0.066,0.26 --position-std-m 0.001 --heading-std-rad 0.002 \
        --wheel-noise 1e-6 --out "$WORK/out/calib.json" > /dev/null
    end=$EPOCHREALTIME
    runs+=("$(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.3f", b - a }')")
done
echo "log_duration_s $DURATION_S"
echo "calibrate_wall_clock_s ${runs[*]}"
