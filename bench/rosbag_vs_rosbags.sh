#!/usr/bin/env bash
# Reading a rosbag2 recording: twindrive's decoder (definitions read from
# the file at run time, CDR by cdr-encoding) against rosbags (Python, the
# distribution's compiled-in definitions) on the same bag, every message of
# every topic, in both storages: MCAP (zstd chunks) and sqlite3 (.db3,
# through SQLite). The bag is `twindrive rosbag` of the office drive (a
# 181-beam LaserScan at 10 Hz, joints, odometry, TF) for DURATION_S.
# Usage: bench/rosbag_vs_rosbags.sh   (from any directory)
#   SMOKE=1   a 10 s drive
#   PEERS=0   twindrive's side only
set -euo pipefail
SMOKE=${SMOKE:-0}
PEERS=${PEERS:-1}
DURATION_S=600
if [[ $SMOKE == 1 ]]; then
    DURATION_S=10
fi
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
source bench/profile.sh
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

value_of() { awk -v k="$1" '$1 == k { v = $2 } END { if (v == "") exit 1; print v }'; }

build -p twindrive --bin twindrive
build -p twindrive-ros --example bag_decode
./target/$PROFILE_DIR/twindrive simulate scenarios/office_drive.toml --duration-s "$DURATION_S" --out "$WORK/sim" > /dev/null
for storage in mcap sqlite3; do
    bag=$WORK/bag_$storage
    ./target/$PROFILE_DIR/twindrive rosbag "$WORK/sim" --scenario scenarios/office_drive.toml --storage "$storage" --out "$bag" > /dev/null
    out=$(./target/$PROFILE_DIR/examples/bag_decode "$bag")
    messages=$(value_of messages <<<"$out")
    td=$(value_of twindrive_decode_s <<<"$out")
    size=$(du -k "$bag" | awk '{ print $1 }')
    echo "== $storage bag: $messages messages, $size kB (office drive, $DURATION_S s)"
    if [[ $PEERS != 1 ]]; then
        printf '%-12s %10s\n' decoder "seconds"
        printf '%-12s %10s\n' twindrive "$td"
        continue
    fi
    PY=$(bash scripts/ros-deps.sh)
    peer=$("$PY" bench/ros/rosbags_decode.py "$bag")
    rb=$(value_of rosbags_decode_s <<<"$peer")
    [[ $(value_of messages <<<"$peer") == "$messages" ]] || { echo "the decoders counted different messages" >&2; exit 1; }
    printf '%-12s %10s %14s\n' decoder seconds "messages/s"
    awk -v n="$messages" -v t="$td" -v r="$rb" -v s="$storage" 'BEGIN {
        printf "%-12s %10.3f %14.0f\n", "rosbags", r, n / r
        printf "%-12s %10.3f %14.0f\n", "twindrive", t, n / t
        printf "%s: twindrive is %.1fx rosbags\n", s, r / t
    }'
done
