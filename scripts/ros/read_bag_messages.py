"""Reads every message of a rosbag2 recording with `rosbags` and prints, as
JSON, what a test needs to check another writer message for message:

  {"distro": "humble"|"jazzy",
   "messages": [[topic, log_time_ns, sha256 hex of the raw data], ...],
   "topics": {name: {"type": ..., "count": N, "fields": [field names of
              the first message as rosbags deserializes it]}}}

Messages are in log-time order, ties in storage order. The raw data is
what rosbags hands out (decompressed for message-compressed bags). BAG is
what bag_counts.py takes: a bag directory, a storage file, or a directory
of storage files without metadata.yaml.

Every message is deserialized with rosbags' own type store of the bag's
distribution (metadata.yaml's ros_distro, else the .db3's schema table,
else --distro, jazzy by default): irobot_create_msgs as check_bag.py
defines it, and types that store lacks as the bag defines them. A message
that does not deserialize, or a type nobody defines, is an error (exit 1).

usage: read_bag_messages.py BAG [--distro humble|jazzy]
"""

import argparse
import dataclasses
import hashlib
import json
import sqlite3
import sys
import tempfile
from contextlib import ExitStack
from pathlib import Path

from rosbags.rosbag2 import Reader

from bag_counts import sources
from bag_variants import DISTROS, type_store


def sqlite_distro(src: Path):
    """ros_distro of the schema table of the source's first .db3 (Humble and later)."""
    files = sorted(src.glob("*.db3")) if src.is_dir() else [src] if src.suffix == ".db3" else []
    for f in files:
        conn = sqlite3.connect(f"file:{f}?immutable=1", uri=True)
        try:
            row = conn.execute("SELECT ros_distro FROM schema").fetchone()
        except sqlite3.Error:
            row = None
        finally:
            conn.close()
        return row[0] if row else None
    return None


class Fatal(Exception):
    """A type without a definition, or a message that does not deserialize."""


def read(bag: Path, tmp: Path, default_distro: str):
    paths, _, _ = sources(bag, tmp)
    with ExitStack() as stack:
        readers = [stack.enter_context(Reader(p)) for p in paths]
        conns = [c for r in readers for c in r.connections]
        named = readers[0].ros_distro if readers[0].ros_distro in DISTROS else sqlite_distro(paths[0])
        distro = named if named in DISTROS else default_distro
        store = type_store(distro, conns)
        unknown = sorted({c.msgtype for c in conns if c.msgtype not in store.fielddefs})
        if unknown:
            raise Fatal(f"no definition of {', '.join(unknown)} in rosbags' {distro} types or the bag")
        topics = {c.topic: {"type": c.msgtype, "count": 0, "fields": None} for c in conns}
        messages = []
        for reader in readers:
            for c, t, raw in reader.messages():
                try:
                    msg = store.deserialize_cdr(raw, c.msgtype)
                except Exception as e:  # noqa: BLE001 - any failure is the finding
                    raise Fatal(f"{c.topic} at {t} ns: rosbags cannot deserialize {c.msgtype} "
                                f"({len(raw)} bytes): {type(e).__name__}: {e}") from None
                info = topics[c.topic]
                info["count"] += 1
                if info["fields"] is None:
                    info["fields"] = [f.name for f in dataclasses.fields(msg)
                                      if f.name != "__msgtype__" and not f.name.isupper()]
                messages.append([c.topic, t, hashlib.sha256(raw).hexdigest()])
    messages.sort(key=lambda m: m[1])  # stable: ties keep storage order
    return distro, topics, messages


def main():
    ap = argparse.ArgumentParser(description="Every message of a rosbag2 bag as rosbags reads it.")
    ap.add_argument("bag", type=Path)
    ap.add_argument("--distro", choices=sorted(DISTROS), default="jazzy",
                    help="when neither metadata.yaml nor the .db3 names one (default jazzy)")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        try:
            distro, topics, messages = read(a.bag, Path(tmp), a.distro)
        except Fatal as e:
            sys.exit(f"{a.bag}: {e}")
        except Exception as e:  # noqa: BLE001 - rosbags' errors, reported plainly
            sys.exit(f"{a.bag}: rosbags cannot read it: {type(e).__name__}: {e}")
    json.dump({"distro": distro, "messages": messages, "topics": dict(sorted(topics.items()))},
              sys.stdout)
    print()


if __name__ == "__main__":
    main()
