#!/usr/bin/env bash
# The whole test suite: formatting, lints, every benchmark in smoke mode,
# every test in the workspace. Needs the Rust toolchain (with rustfmt and
# clippy), Node.js's npm (the console's pinned front-end libraries) and
# python3 with venv and pip; installs Debian's chromium and chromium-driver
# for the console's browser tests when they are missing, and the pinned
# Python ROS 2 peers (rosbags, mcap-ros2-support) the ROS interop tests
# check against. Run from anywhere.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

cargo fmt --all --check
cargo clippy --workspace --all-targets -- -D warnings
# Every benchmark in smoke mode, twindrive's side (the Python peers stay out
# of CI): a change that breaks a benchmark fails here.
PEERS=0 bash bench/smoke.sh
bash scripts/browser-deps.sh
bash scripts/ros-deps.sh >/dev/null
cargo test --workspace
