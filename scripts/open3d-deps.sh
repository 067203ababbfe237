#!/usr/bin/env bash
# Open3D, the peer of bench/scan_match_vs_open3d.sh: `open3d-cpu` (the
# CPU-only wheel) and numpy, pinned, in .venv-open3d at the repository root,
# and the two shared libraries its wheel loads that a minimal Debian lacks
# (libusb-1.0, libgomp1; apt). Prints the venv's python. Does nothing when
# they are installed. Only the benchmark needs it; CI's smoke run does not.
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV=$ROOT/.venv-open3d
PINS=(open3d-cpu==0.20.0 numpy==2.4.6)

if ! ldconfig -p | grep -q 'libusb-1.0.so.0' || ! ldconfig -p | grep -q 'libgomp.so.1'; then
    SUDO=()
    if [[ $(id -u) -ne 0 ]]; then
        SUDO=(sudo)
    fi
    echo "open3d-deps: installing libusb-1.0-0 and libgomp1 (apt)" >&2
    "${SUDO[@]}" apt-get update -qq
    DEBIAN_FRONTEND=noninteractive "${SUDO[@]}" apt-get install -y -qq --no-install-recommends \
        libusb-1.0-0 libgomp1 >/dev/null
fi
bash "$ROOT/scripts/pinned-venv.sh" open3d-deps "$VENV" "${PINS[@]}"
