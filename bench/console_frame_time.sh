#!/usr/bin/env bash
# The console's map in a real browser (headless Debian chromium over
# WebDriver) with a one-hour mission (360,000 samples) as the rehearsal and
# its plan drawn: the draw time per frame while panning (target under
# 16 ms) and the interval between animation frames.
# Usage: bench/console_frame_time.sh   (SMOKE=1: a 60 s mission, 60 frames, a dev build)
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
bash scripts/browser-deps.sh
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
source bench/profile.sh
if [ "${SMOKE:-0}" = 1 ]; then
    DURATION=60; FRAMES=60
else
    DURATION=3600; FRAMES=300
fi
build -p twindrive --bin twindrive --example console_frame_time
BIN="target/$PROFILE_DIR"
"$BIN/twindrive" simulate scenarios/wall_following.toml --duration-s "$DURATION" --out "$TMP/mission" >/dev/null 2>&1
"$BIN/examples/console_frame_time" --twindrive "$BIN/twindrive" --rehearsal "$TMP/mission" --frames "$FRAMES"
