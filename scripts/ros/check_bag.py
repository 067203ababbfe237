"""Reads a rosbag2 recording twindrive wrote with two independent decoders
and prints what they found as JSON.

1. `rosbags` with the standard message definitions of the distribution
   (its own type store, not the definitions in the file): the bytes must be
   what a ROS 2 node of that distribution sends. rosbags also parses
   `metadata.yaml`.
2. `mcap-ros2-support` with the definitions stored in the file.

Both must agree on every message; the output has, per topic, the type, the
count and the first and last message as plain JSON, for the Rust test to
compare with the log.

usage: check_bag.py BAG_DIR humble|jazzy
"""

import dataclasses
import json
import math
import sys
from pathlib import Path

from mcap_ros2.reader import read_ros2_messages
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

# irobot_create_msgs is not in rosbags' stores; this is its definition
# (irobot_create_msgs/msg/HazardDetection.msg and HazardDetectionVector.msg).
IROBOT = {
    "irobot_create_msgs/msg/HazardDetection": """
uint8 BACKUP_LIMIT=0
uint8 BUMP=1
uint8 CLIFF=2
uint8 STALL=3
uint8 WHEEL_DROP=4
uint8 OBJECT_PROXIMITY=5
std_msgs/Header header
uint8 type
""",
    "irobot_create_msgs/msg/HazardDetectionVector": """
std_msgs/Header header
irobot_create_msgs/HazardDetection[] detections
""",
}


def plain(value):
    """A message (either library's) as JSON-ready Python values."""
    if dataclasses.is_dataclass(value):
        return {
            f.name: plain(getattr(value, f.name))
            for f in dataclasses.fields(value)
            if f.name != "__msgtype__" and not f.name.isupper()  # constants
        }
    if hasattr(value, "tolist"):
        return plain(value.tolist())
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if hasattr(value, "__slots__"):
        return {k: plain(getattr(value, k)) for k in value.__slots__}
    if isinstance(value, float) and math.isnan(value):
        return "NaN"
    if isinstance(value, float) and math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return value


def with_rosbags(bag: Path, distro: str) -> dict:
    store = get_typestore(Stores.ROS2_HUMBLE if distro == "humble" else Stores.ROS2_JAZZY)
    for name, text in IROBOT.items():
        store.register(get_types_from_msg(text, name))
    topics = {}
    with Reader(bag) as reader:
        for conn in reader.connections:
            topics[conn.topic] = {"type": conn.msgtype, "count": 0, "first": None, "last": None,
                                  "metadata_count": conn.msgcount}
        for conn, _t, raw in reader.messages():
            msg = plain(store.deserialize_cdr(raw, conn.msgtype))
            t = topics[conn.topic]
            t["count"] += 1
            if t["first"] is None:
                t["first"] = msg
            t["last"] = msg
    return topics


def with_mcap_ros2(bag: Path) -> dict:
    topics = {}
    for path in sorted(bag.glob("*.mcap")):
        for m in read_ros2_messages(str(path)):
            t = topics.setdefault(m.channel.topic, {"type": m.schema.name, "count": 0,
                                                    "first": None, "last": None})
            msg = plain(m.ros_msg)
            t["count"] += 1
            if t["first"] is None:
                t["first"] = msg
            t["last"] = msg
    return topics


def main():
    bag, distro = Path(sys.argv[1]), sys.argv[2]
    a = with_rosbags(bag, distro)
    b = with_mcap_ros2(bag)
    # A topic with no messages has a connection but nothing for a message reader.
    if {t for t in a if a[t]["count"] > 0} != set(b):
        sys.exit(f"the decoders see different topics: {sorted(a)} vs {sorted(b)}")
    for topic in b:
        for key in ("type", "count", "first", "last"):
            if a[topic][key] != b[topic][key]:
                sys.exit(f"{topic}: `{key}` differs:\n rosbags: {a[topic][key]}\n mcap_ros2: {b[topic][key]}")
    for topic in a:
        if a[topic]["metadata_count"] != a[topic]["count"]:
            sys.exit(f"{topic}: metadata.yaml says {a[topic]['metadata_count']} messages, the file has {a[topic]['count']}")
    for t in a.values():
        t["first"], t["last"] = compact(t["first"]), compact(t["last"])
    json.dump(a, sys.stdout)


def compact(value):
    """Long lists (an occupancy grid's cells) as their length and value counts."""
    if isinstance(value, dict):
        return {k: compact(v) for k, v in value.items()}
    if isinstance(value, list):
        if len(value) > 64 and all(isinstance(v, int) for v in value):
            counts = {}
            for v in value:
                counts[str(v)] = counts.get(str(v), 0) + 1
            return {"len": len(value), "counts": counts}
        return [compact(v) for v in value]
    return value


if __name__ == "__main__":
    main()
