"""Counts what `rosbags` reads from rosbag2 recordings, by iterating every
message (not from metadata.yaml), and prints a JSON list, one object a bag:

  {"path": ..., "storage": "sqlite3"|"mcap", "message_count": N,
   "start_ns": first log time, "end_ns": last log time (null when empty),
   "metadata_message_count": what metadata.yaml / the storage index says,
   "files": [storage files read],
   "topics": {name: {"type": ..., "count": ..., "serialization_format": ...}}}

BAG is a bag directory with metadata.yaml, a single .db3/.mcap file, or a
directory without metadata.yaml (a recorder that died): then rosbags reads
each storage file on its own (in rosbag2's reindex order, <bag>_<n>.<ext>
by n) and the counts are summed; *.zstd files (file compression) are
decompressed to a temporary file first. A bag rosbags cannot read gets
{"path": ..., "error": "..."} and the exit status is 1.

usage: bag_counts.py BAG [BAG ...]
"""

import argparse
import json
import re
import shutil
import sys
import tempfile
from pathlib import Path, PurePath

from rosbags.rosbag2 import Reader
from ruamel.yaml import YAML

if sys.version_info >= (3, 14):
    from compression import zstd
else:  # rosbags' own dependency before 3.14
    from backports import zstd

STORAGE = {".db3": "sqlite3", ".mcap": "mcap"}


def storage_files(d: Path):
    """A directory's storage files in rosbag2's reindex order."""
    files = [p for p in d.iterdir()
             if p.is_file() and p.name.removesuffix(".zstd").endswith(tuple(STORAGE))]

    def key(p: Path):
        m = re.match(r".+_(\d+)\.[a-zA-Z0-9]+$", p.name.removesuffix(".zstd"))
        return (0, int(m.group(1)), p.name) if m else (1, 0, p.name)
    return sorted(files, key=key)


def sources(path: Path, tmp: Path):
    """What rosbags' Reader can open for a bag: (paths, storage, storage file
    names). A directory with metadata.yaml is one source; otherwise each
    storage file is, *.zstd ones decompressed into `tmp`."""
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist")
    if path.is_dir() and (path / "metadata.yaml").exists():
        info = YAML(typ="safe").load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        names = [PurePath(p).name for p in info["relative_file_paths"]]
        return [path], info["storage_identifier"], names
    files = storage_files(path) if path.is_dir() else [path]
    if not files:
        raise ValueError("no metadata.yaml and no .db3/.mcap files")
    readable = []
    for f in files:
        if f.suffix == ".zstd":
            plain = tmp / f.name.removesuffix(".zstd")
            with f.open("rb") as src, zstd.open(src, "rb") as z, plain.open("wb") as dst:
                shutil.copyfileobj(z, dst)
            readable.append(plain)
        else:
            readable.append(f)
    storages = {STORAGE.get(f.suffix) for f in readable}
    if len(storages) != 1 or None in storages:
        raise ValueError(f"not one storage format: {sorted(f.name for f in files)}")
    return readable, storages.pop(), [f.name for f in files]


def count(path: Path) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        return tally(path, *sources(path, Path(tmp)))


def tally(path: Path, sources, storage: str, names) -> dict:
    out = {"path": str(path), "storage": storage, "message_count": 0, "start_ns": None,
           "end_ns": None, "metadata_message_count": 0, "files": names, "topics": {}}
    for src in sources:
        with Reader(src) as reader:
            out["metadata_message_count"] += reader.message_count
            topics = out["topics"]
            for c in reader.connections:
                t = topics.setdefault(c.topic, {"type": c.msgtype, "count": 0,
                                                "serialization_format": c.ext.serialization_format})
                if t["type"] != c.msgtype:
                    t["type"] = sorted({t["type"], c.msgtype})
            for c, ts, _ in reader.messages():
                topics[c.topic]["count"] += 1
                out["message_count"] += 1
                out["start_ns"] = ts if out["start_ns"] is None else min(out["start_ns"], ts)
                out["end_ns"] = ts if out["end_ns"] is None else max(out["end_ns"], ts)
    out["topics"] = dict(sorted(out["topics"].items()))
    return out


def main():
    ap = argparse.ArgumentParser(description="Count the messages rosbags reads from rosbag2 bags.")
    ap.add_argument("bags", type=Path, nargs="+")
    a = ap.parse_args()
    results, failed = [], False
    for bag in a.bags:
        try:
            results.append(count(bag))
        except Exception as e:  # noqa: BLE001 - reported per bag
            results.append({"path": str(bag), "error": f"{type(e).__name__}: {e}"})
            failed = True
    json.dump(results, sys.stdout, indent=1)
    print()
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
