#!/usr/bin/env bash
# Side-by-side throughput: ir-sim (Python, headless) vs twindrive's simulator on
# the same setup (bench/irsim/run_irsim.py describes it), with and without lidar.
# Usage: bench/sim_vs_irsim.sh   (from any directory)
#   SMOKE=1   tiny step counts (seconds): checks that both sides still run
#   PEERS=0   twindrive's side only (no Python, no ir-sim)
set -euo pipefail

IRSIM_VERSION=2.12.0
SMOKE=${SMOKE:-0}
PEERS=${PEERS:-1}
if [[ $SMOKE == 1 ]]; then
    IRSIM_STEPS=${IRSIM_STEPS:-20}
    IRSIM_STEPS_NOSENSOR=${IRSIM_STEPS_NOSENSOR:-200}
    TWINDRIVE_STEPS=${TWINDRIVE_STEPS:-2000}
fi
IRSIM_STEPS=${IRSIM_STEPS:-2000}              # lidar variant, ~7 s here
IRSIM_STEPS_NOSENSOR=${IRSIM_STEPS_NOSENSOR:-20000}
TWINDRIVE_STEPS=${TWINDRIVE_STEPS:-200000}

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV=$ROOT/.venv-irsim
cd "$ROOT"
source bench/profile.sh

# last "<key> <float>" line of stdin
value_of() { awk -v k="$1" '$1 == k { v = $2 } END { if (v == "") exit 1; print v }'; }

irsim() {
    MPLBACKEND=Agg "$VENV/bin/python" bench/irsim/run_irsim.py "$@" | value_of irsim_steps_per_s
}
build -p twindrive-sim --example throughput
twindrive() {
    example_bin throughput "$1" --steps "$TWINDRIVE_STEPS" | value_of steps_per_s
}

echo "twindrive, lidar ..." >&2
td_lidar=$(twindrive bench/irsim_setup.toml)
echo "twindrive, no sensor ..." >&2
td_none=$(twindrive bench/irsim_setup_nosensor.toml)

if [[ $PEERS != 1 ]]; then
    printf '%-26s %17s\n' setup "twindrive steps/s"
    printf '%-26s %17.1f\n' "lidar 360 beams, 6 obst." "$td_lidar" "no sensor, 6 obst." "$td_none"
    exit 0
fi

if [[ ! -x $VENV/bin/python ]]; then
    python3 -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --disable-pip-version-check "ir-sim==$IRSIM_VERSION" >&2
echo "ir-sim $IRSIM_VERSION, lidar ..." >&2
irsim_lidar=$(irsim --steps "$IRSIM_STEPS")
echo "ir-sim $IRSIM_VERSION, no sensor ..." >&2
irsim_none=$(irsim --steps "$IRSIM_STEPS_NOSENSOR" --no-sensor)

row() { awk -v s="$1" -v a="$2" -v b="$3" 'BEGIN { printf "%-26s %14.1f %17.1f %9.1fx\n", s, a, b, b / a }'; }
printf '%-26s %14s %17s %10s\n' setup "ir-sim steps/s" "twindrive steps/s" ratio
row "lidar 360 beams, 6 obst." "$irsim_lidar" "$td_lidar"
row "no sensor, 6 obst." "$irsim_none" "$td_none"
