#!/usr/bin/env bash
# The independent ROS 2 implementations the ROS interop tests check
# twindrive against: `rosbags` (a pure-Python rosbag2 reader/writer with its
# own CDR serializer, RIHS01 type hashes and the standard message types of
# each distribution), `mcap-ros2-support` (Foxglove's decoder, which reads
# the definitions stored in the file), `eclipse-zenoh` (the fake ROS 2
# driver's session) and `mujoco` (the physics engine the fake driver can
# put behind it). Pinned, in .venv-ros at the repository root. Prints
# the venv's python. Does nothing when they are installed.
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV=$ROOT/.venv-ros
PINS=(rosbags==0.11.9 mcap-ros2-support==0.6.0 mcap==1.6.0 eclipse-zenoh==1.10.2 mujoco==3.3.7)

bash "$ROOT/scripts/pinned-venv.sh" ros-deps "$VENV" "${PINS[@]}"
