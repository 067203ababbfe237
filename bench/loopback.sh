#!/usr/bin/env bash
# Two real processes on loopback with zenoh in between, no emulation: plan
# upload throughput (MB/s) and the round trip of a message and its answer
# (ms). Three runs, so the spread shows.
# Usage: bench/loopback.sh           (SMOKE=1: 1 MB and 20 pings, once)
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
source bench/profile.sh
build -p twindrive-net --example loopback
if [ "${SMOKE:-0}" = 1 ]; then
    example_bin loopback --smoke
    exit 0
fi
for run in 1 2 3; do
    echo "run $run"
    example_bin loopback --mb 32 --pings 500
done
