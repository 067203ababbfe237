#!/usr/bin/env bash
# The whole test suite: formatting, lints, every benchmark in smoke mode,
# every test in the workspace. Needs only the Rust toolchain (with rustfmt and
# clippy); run from anywhere.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

cargo fmt --all --check
cargo clippy --workspace --all-targets -- -D warnings
# Every benchmark in smoke mode, twindrive's side (the Python peers stay out
# of CI): a change that breaks a benchmark fails here.
PEERS=0 bash bench/smoke.sh
cargo test --workspace
