#!/usr/bin/env bash
# Every benchmark in smoke mode: tiny sizes, a few seconds each, on the dev
# build the tests use (bench/profile.sh), so that a change that breaks a
# benchmark is caught before it lands. The numbers it prints mean nothing.
# Usage: bench/smoke.sh            (from any directory; with the Python peers)
#        PEERS=0 bench/smoke.sh    (twindrive's side only: what scripts/test.sh runs)
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
export SMOKE=1
export PEERS=${PEERS:-1}
# The dev build the tests use, every binary and example in it, with the
# whole workspace's features (nothing to do after scripts/test.sh's build);
# the scripts run what it built rather than `cargo run -p`, which would
# build shared dependencies again for one package's features.
cargo test --workspace --no-run -q

for script in sim_vs_irsim.sh ekf_vs_filterpy.sh prune_vs_distance_matrix.sh route_vs_python.sh calibrate_one_hour.sh rosbag_vs_rosbags.sh scan_match_vs_open3d.sh self_calibrate.sh map.sh slam_benchmark.sh slam_paths.sh; do
    echo "== bench/$script (smoke, peers $PEERS)" >&2
    bash "bench/$script"
done
echo "== upload efficiency (smoke; twindrive experiment upload)" >&2
target/debug/twindrive experiment upload --smoke --seeds 1
echo "== loopback, two processes over zenoh (smoke; a dev build, the one the tests use)" >&2
target/debug/examples/loopback --smoke
echo "== the console: frame time in the browser, a fleet's telemetry to pages (smoke)" >&2
bash bench/console_frame_time.sh
bash bench/console_fleet.sh
echo "== the criterion benches, each benchmark once (test mode, the dev build)" >&2
cargo test -q --workspace --benches
echo "bench smoke: all benchmarks ran"
