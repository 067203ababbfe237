#!/usr/bin/env bash
# Debian's chromium and chromium-driver for the console's browser tests
# (crates/twindrive/tests/console.rs) and its frame-time benchmark: both in
# one apt run, so their versions match. Does nothing when both are there
# with the same version.
set -euo pipefail

version() { "$1" --version 2>/dev/null | grep -oE '[0-9]+\.[0-9]+\.[0-9]+' | head -1; }

if [[ -x /usr/bin/chromium && -x /usr/bin/chromedriver ]] \
    && [[ "$(version /usr/bin/chromium)" == "$(version /usr/bin/chromedriver)" ]]; then
    exit 0
fi
SUDO=()
if [[ $(id -u) -ne 0 ]]; then
    SUDO=(sudo)
fi
echo "browser-deps: installing chromium and chromium-driver (apt)" >&2
"${SUDO[@]}" apt-get update -qq
DEBIAN_FRONTEND=noninteractive "${SUDO[@]}" apt-get install -y -qq --no-install-recommends \
    chromium chromium-driver >/dev/null
echo "browser-deps: $(/usr/bin/chromium --version); $(/usr/bin/chromedriver --version)" >&2
