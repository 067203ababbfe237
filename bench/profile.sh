# Sourced by the benchmark scripts: the cargo profile to build with. A real
# run measures the release build; SMOKE=1 only checks that a script still
# runs, so it uses the dev build the tests use (dependencies optimised, the
# workspace at opt-level 1) and CI builds the workspace once, not twice.
if [[ ${SMOKE:-0} == 1 ]]; then
    PROFILE_FLAG=()
    PROFILE_DIR=debug
else
    PROFILE_FLAG=(--release)
    PROFILE_DIR=release
fi
