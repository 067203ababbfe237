#!/usr/bin/env bash
# The whole test suite: formatting, lints, every benchmark in smoke mode,
# every test in the workspace, the book built and its links checked. Needs
# the Rust toolchain (with rustfmt and clippy; cargo-nextest runs the tests
# where it is installed), Node.js's npm (the console's
# pinned front-end libraries) and python3 with venv and pip; installs
# Debian's chromium and chromium-driver for the console's browser tests when
# they are missing, the pinned Python ROS 2 peers (rosbags,
# mcap-ros2-support) the ROS interop tests check against, and the pinned
# mdBook (scripts/docs.sh). Run from anywhere. Prints the time of each stage
# at the end.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

STAGES=()
stage() {
    local name=$1 start=$SECONDS
    shift
    echo "== $name" >&2
    "$@"
    STAGES+=("$(printf '%6d s  %s' $((SECONDS - start)) "$name")")
}
report() {
    local status=$?
    echo "== stage times (total ${SECONDS} s)" >&2
    printf '%s\n' "${STAGES[@]}" >&2
    exit $status
}
trap report EXIT

# A job started in the background: wait for it and show what it printed.
finish() {
    local pid=$1 log=$2 what=$3
    if ! wait "$pid"; then
        cat "$log" >&2
        echo "$what failed" >&2
        return 1
    fi
    cat "$log" >&2
}

# The test peers (Debian's chromium, the Python ROS 2 packages) install in
# the background while the workspace builds.
DEPS_LOG=$(mktemp)
(bash scripts/browser-deps.sh && bash scripts/ros-deps.sh >/dev/null) >"$DEPS_LOG" 2>&1 &
DEPS_PID=$!
wait_for_deps() { finish "$DEPS_PID" "$DEPS_LOG" "installing the test peers"; }

# mdBook (scripts/docs.sh) compiles from crates.io in the background too,
# at a lower priority than the workspace's build; nothing to do when it is
# already installed.
DOCS_LOG=$(mktemp)
nice -n 10 bash scripts/docs.sh --install-only >"$DOCS_LOG" 2>&1 &
DOCS_PID=$!
build_docs() { finish "$DOCS_PID" "$DOCS_LOG" "installing mdbook" && bash scripts/docs.sh; }

# Links first: a broken one fails in a second, not after the build.
stage "links in README and the book" python3 scripts/check_links.py
stage "cargo fmt --check" cargo fmt --all --check
stage "cargo clippy" cargo clippy --workspace --all-targets -- -D warnings
stage "build the tests" cargo test --workspace --no-run
stage "test peers (chromium, Python ROS 2 packages)" wait_for_deps
# Every benchmark in smoke mode, twindrive's side (the Python peers stay out
# of CI), on the dev build: a change that breaks a benchmark fails here.
stage "benchmarks, smoke mode" env PEERS=0 bash bench/smoke.sh
# Every test. cargo-nextest runs the tests of every binary side by side (the
# machine's cores stay busy across binaries, where cargo test waits for each
# binary's slowest test); doc tests are cargo test's alone. Plain cargo test
# where nextest is missing.
if cargo nextest --version >/dev/null 2>&1; then
    stage "tests (cargo nextest)" cargo nextest run --workspace --no-fail-fast
    stage "doc tests" cargo test --workspace --doc
else
    stage "cargo test" cargo test --workspace
fi
stage "the book: mdbook build, links" build_docs
