# Sourced by the benchmark scripts: where the binaries they run are. A real
# run measures the release build; SMOKE=1 only checks that a script still
# runs, so it uses the dev build the tests use (dependencies optimised, the
# workspace at opt-level 1) and CI builds the workspace once, not twice.
if [[ ${SMOKE:-0} == 1 ]]; then
    PROFILE_DIR=debug
else
    PROFILE_DIR=release
fi

# build ARGS...: builds what a benchmark runs (`-p PKG --example NAME`,
# `-p twindrive`). A real run builds the release profile. In smoke mode it
# builds nothing: `cargo test --workspace --no-run` (which bench/smoke.sh
# runs first, and which CI's build already did) built every binary and
# example with the whole workspace's features, and a `cargo build -p` of
# one package resolves features for that package alone, so it would build
# shared dependencies (zenoh among them) again in other variants.
build() {
    if [[ ${SMOKE:-0} == 1 ]]; then
        return 0
    fi
    cargo build --release -q "$@"
}

# example NAME ARGS...: runs an example `build` built.
example_bin() {
    local name=$1
    shift
    "$ROOT/target/$PROFILE_DIR/examples/$name" "$@"
}
