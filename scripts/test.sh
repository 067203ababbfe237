#!/usr/bin/env bash
# The whole test suite: formatting, lints, every test in the workspace.
# Needs only the Rust toolchain (with rustfmt and clippy); run from anywhere.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

cargo fmt --all --check
cargo clippy --workspace --all-targets -- -D warnings
cargo test --workspace
