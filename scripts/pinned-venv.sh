#!/usr/bin/env bash
# pinned-venv.sh NAME VENV PIN...: a Python virtualenv at VENV holding
# exactly the pinned packages (pip `name==version`), made or completed when
# a pin is missing. Prints the venv's python; NAME prefixes what it says on
# stderr. The peers' scripts (ros-deps.sh, open3d-deps.sh) call it.
set -euo pipefail
NAME=$1
VENV=$2
shift 2
PINS=("$@")

if [[ ! -x $VENV/bin/python ]]; then
    python3 -m venv "$VENV"
fi
installed=$("$VENV/bin/python" -m pip freeze 2>/dev/null || true)
missing=0
for pin in "${PINS[@]}"; do
    grep -qx "$pin" <<<"$installed" || missing=1
done
if [[ $missing == 1 ]]; then
    echo "$NAME: installing ${PINS[*]} into $VENV" >&2
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check "${PINS[@]}" >&2
fi
echo "$VENV/bin/python"
