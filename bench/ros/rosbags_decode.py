"""Decodes every message of a rosbag2 recording with rosbags (the peer of
crates/ros/examples/bag_decode.rs): opening the bag and deserializing each
message with the Jazzy type store. Prints the count and the best of
REPEAT runs.

usage: rosbags_decode.py BAG [REPEAT]
"""

import sys
import time
from pathlib import Path

from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts" / "ros"))
from check_bag import IROBOT  # noqa: E402

store = get_typestore(Stores.ROS2_JAZZY)
for name, text in IROBOT.items():
    store.register(get_types_from_msg(text, name))
bag = Path(sys.argv[1])
repeat = int(sys.argv[2]) if len(sys.argv) > 2 else 3
best = float("inf")
for _ in range(repeat):
    started = time.perf_counter()
    n = 0
    with Reader(bag) as reader:
        for conn, _t, raw in reader.messages():
            store.deserialize_cdr(raw, conn.msgtype)
            n += 1
    best = min(best, time.perf_counter() - started)
print(f"messages {n}")
print(f"rosbags_decode_s {best:.4f}")
