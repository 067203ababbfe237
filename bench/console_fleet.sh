#!/usr/bin/env bash
# The console serving 20 robots' telemetry to three open pages: a zenoh
# router, 20 robot agents (each a simulated site at real time) and one
# console on loopback; three WebSocket clients count what the pages would
# receive. Prints the console's CPU and memory and each page's message and
# byte rates while every robot executes its plan.
# Usage: bench/console_fleet.sh   (SMOKE=1: 3 robots, 2 pages, 3 s, a dev build)
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
source bench/profile.sh
if [ "${SMOKE:-0}" = 1 ]; then
    ARGS=(--robots 3 --pages 2 --seconds 3)
else
    ARGS=(--robots 20 --pages 3 --seconds 20)
fi
build -p twindrive --bin twindrive --example console_fleet
BIN="target/$PROFILE_DIR"
"$BIN/twindrive" simulate scenarios/wall_following.toml --duration-s 120 --out "$TMP/mission" >/dev/null 2>&1
"$BIN/examples/console_fleet" --twindrive "$BIN/twindrive" --rehearsal "$TMP/mission" "${ARGS[@]}"
