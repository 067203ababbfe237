"""Rewrites one rosbag2 recording in every storage layout a reader meets in
the field, with `rosbags` (an independent rosbag2 implementation) wherever
it can write the layout and Python's sqlite3 where it cannot. Every variant
holds the same messages: the same raw CDR bytes, log times, topics, types
and serialization formats as IN_BAG, with the message definitions the input
stores (or rosbags' Jazzy ones where it stores none).

OUT_DIR/<variant>/ is a complete bag directory:

  sqlite3_v8, sqlite3_v9, mcap_v8, mcap_v9
      rosbags' writer, metadata versions 8 and 9 (rosbags names the storage
      file <variant>.db3 / <variant>.mcap, ros_distro: rosbags).
  sqlite3_file_zstd, mcap_file_zstd
      rosbags' file compression: the storage file as one zstd frame,
      <variant>.db3.zstd / .mcap.zstd, compression_mode: file.
  sqlite3_message_zstd
      rosbags' message compression: each message's data one zstd frame.
  sqlite3_split, mcap_split
      three storage files split by log time (<variant>_0.db3, _1, _2, each
      written by rosbags with every topic) and a merged metadata.yaml
      (version 9, rosbags' layout) listing all three.
  sqlite3_split_no_metadata, mcap_split_no_metadata
      the same without metadata.yaml (a recorder that died); file name
      order is time order.
  sqlite3_v4 .. sqlite3_v7, mcap_v5, mcap_v7
      the v8 bag's storage file (renamed <variant>_0.db3 / .mcap) with a
      metadata.yaml in the layout rosbag2's yaml-cpp emitter wrote at that
      version (field set and order from rosbag2_storage's metadata_io.cpp /
      yaml.hpp; v4 as Foxy/Galactic, v5 as Humble).
  sqlite3_foxy
      Foxy/Galactic's .db3: tables topics and messages only (no type
      definitions), WAL journal as Foxy's writer left it, metadata v4.
  sqlite3_humble
      Humble's .db3 (rosbag2 0.15.4 and later): schema (version 3,
      ros_distro humble), an empty metadata table, topics, messages; no
      message_definitions; metadata v5.

Prints one line per variant. Same input, same bytes.

usage: bag_variants.py IN_BAG OUT_DIR [--force]
"""

import argparse
import shutil
import sqlite3
import tempfile
from io import StringIO
from pathlib import Path
from typing import NamedTuple

from rosbags.interfaces import MessageDefinitionFormat
from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
from ruamel.yaml import YAML

from check_bag import IROBOT

DISTROS = {"humble": Stores.ROS2_HUMBLE, "jazzy": Stores.ROS2_JAZZY}
EXT = {"sqlite3": "db3", "mcap": "mcap"}
PLUGIN = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}
SPLIT_PARTS = 3
IDL_SEP = "=" * 80 + "\n"

# rosbag2's .db3 tables, statement for statement (sqlite_storage.cpp).
FOXY_TABLES = [
    "CREATE TABLE topics(id INTEGER PRIMARY KEY,name TEXT NOT NULL,type TEXT NOT NULL,"
    "serialization_format TEXT NOT NULL,offered_qos_profiles TEXT NOT NULL);",
    "CREATE TABLE messages(id INTEGER PRIMARY KEY,topic_id INTEGER NOT NULL,"
    "timestamp INTEGER NOT NULL, data BLOB NOT NULL);",
    "CREATE INDEX timestamp_idx ON messages (timestamp ASC);",
]
HUMBLE_TABLES = [
    "CREATE TABLE schema(schema_version INTEGER PRIMARY KEY,ros_distro TEXT NOT NULL);",
    "CREATE TABLE metadata(id INTEGER PRIMARY KEY,metadata_version INTEGER NOT NULL,"
    "metadata TEXT NOT NULL);",
] + FOXY_TABLES


class Topic(NamedTuple):
    name: str
    msgtype: str
    msgdef: str
    digest: str
    serialization_format: str
    qos: list


class Bag(NamedTuple):
    topics: list  # [Topic]
    messages: list  # [(topic index, log time ns, raw bytes)], log-time order
    distro: str


class FileInfo(NamedTuple):
    path: str
    start: int
    duration: int
    count: int


def read_bag(path: Path) -> Bag:
    """Every connection and message of a bag (directory or storage file)."""
    with Reader(path) as reader:
        conns = reader.connections
        distro = reader.ros_distro if reader.ros_distro in DISTROS else "jazzy"
        store = type_store(distro, conns)
        topics, index = [], {}
        for c in conns:
            if c.msgtype not in store.fielddefs and c.msgdef.format == MessageDefinitionFormat.NONE:
                raise SystemExit(f"{path}: {c.topic}: no definition of {c.msgtype} in the bag or in rosbags")
            msgdef = c.msgdef.data if c.msgdef.format != MessageDefinitionFormat.NONE else \
                store.generate_msgdef(c.msgtype, ros_version=2)[0]
            digest = c.digest or store.hash_rihs01(c.msgtype)
            key = (c.topic, c.msgtype, c.ext.serialization_format)
            if key not in index:
                index[key] = len(topics)
                topics.append(Topic(c.topic, c.msgtype, msgdef, digest,
                                    c.ext.serialization_format, list(c.ext.offered_qos_profiles)))
        by_id = {c.id: index[(c.topic, c.msgtype, c.ext.serialization_format)] for c in conns}
        messages = [(by_id[c.id], t, bytes(raw)) for c, t, raw in reader.messages()]
    messages.sort(key=lambda m: m[1])  # stable: ties keep storage order
    return Bag(topics, messages, distro)


def type_store(distro: str, connections):
    """rosbags' types of `distro`, irobot_create_msgs as check_bag.py defines
    it, and the types that still lack as the connections define them."""
    store = get_typestore(DISTROS[distro])
    for name, text in IROBOT.items():
        if name not in store.fielddefs:
            store.register(get_types_from_msg(text, name))
    for c in connections:
        if c.msgtype not in store.fielddefs and c.msgdef.format != MessageDefinitionFormat.NONE:
            typs = stored_types(c)
            store.register({k: v for k, v in typs.items() if k not in store.fielddefs})
    return store


def stored_types(conn):
    """The types a connection's stored definition (ros2msg or ros2idl) defines."""
    if conn.msgdef.format == MessageDefinitionFormat.MSG:
        return get_types_from_msg(conn.msgdef.data, conn.msgtype)
    typs = {}
    text = conn.msgdef.data
    parts = [p.split("\n", 1)[1] for p in text.split(IDL_SEP)[1:]] if text.startswith(IDL_SEP) else [text]
    for idl in parts:
        typs.update(get_types_from_idl(idl))
    return typs


def write_rosbags(dst: Path, bag: Bag, messages, storage: str, version: int,
                  mode: CompressionMode = CompressionMode.NONE) -> Path:
    """One bag with rosbags' writer, every topic of `bag`; its storage file."""
    w = Writer(dst, version=version, storage_plugin=PLUGIN[storage])
    w.set_compression(mode, CompressionFormat.ZSTD)
    with w:
        conns = [w.add_connection(t.name, t.msgtype, msgdef=t.msgdef, rihs01=t.digest,
                                  serialization_format=t.serialization_format,
                                  offered_qos_profiles=t.qos)
                 for t in bag.topics]
        for i, t, raw in messages:
            w.write(conns[i], t, raw)
    files = [p for p in dst.iterdir() if p.name != "metadata.yaml"]
    assert len(files) == 1, files
    return files[0]


def split_messages(messages, parts: int):
    """`parts` runs of messages, cut at equal steps of log time (messages at
    one time stay together)."""
    t0, t1 = messages[0][1], messages[-1][1]
    cuts = [t0 + (t1 - t0) * k // parts for k in range(1, parts)]
    runs = [[] for _ in range(parts)]
    for m in messages:
        runs[sum(m[1] >= c for c in cuts)].append(m)
    if not all(runs):
        raise SystemExit("cannot split: a third of the recording's time has no messages")
    return runs


def write_split(dst: Path, bag: Bag, storage: str, with_metadata: bool):
    """rosbags writes each run as a bag named like rosbag2's split files
    (<bag>_<n>); their storage files go into `dst` with one metadata.yaml."""
    dst.mkdir(parents=True)
    metas = []
    with tempfile.TemporaryDirectory() as tmp:
        for n, run in enumerate(split_messages(bag.messages, SPLIT_PARTS)):
            part = Path(tmp) / f"{dst.name}_{n}"
            f = write_rosbags(part, bag, run, storage, 9)
            shutil.move(f, dst / f.name)
            metas.append(YAML(typ="safe").load((part / "metadata.yaml").read_text()))
    if with_metadata:
        (dst / "metadata.yaml").write_text(merged_metadata(metas))


def merged_metadata(metas) -> str:
    """The parts' metadata.yaml (rosbags' layout) as one bag's."""
    info = [m["rosbag2_bagfile_information"] for m in metas]
    out = dict(info[0])
    start = min(i["starting_time"]["nanoseconds_since_epoch"] for i in info)
    end = max(i["starting_time"]["nanoseconds_since_epoch"] + i["duration"]["nanoseconds"] for i in info)
    out["relative_file_paths"] = [p for i in info for p in i["relative_file_paths"]]
    out["files"] = [f for i in info for f in i["files"]]
    out["starting_time"] = {"nanoseconds_since_epoch": start}
    out["duration"] = {"nanoseconds": end - start}
    out["message_count"] = sum(i["message_count"] for i in info)
    topics = [dict(t) for t in info[0]["topics_with_message_count"]]
    for k, t in enumerate(topics):
        t["message_count"] = sum(i["topics_with_message_count"][k]["message_count"] for i in info)
    out["topics_with_message_count"] = topics
    yaml = YAML(typ="safe")
    yaml.default_flow_style = False
    s = StringIO()
    yaml.dump({"rosbag2_bagfile_information": out}, s)
    return s.getvalue()


# --- rosbag2's own metadata.yaml (yaml-cpp's block emitter) ---------------

def qos_fields(q, version: int) -> dict:
    enum = (lambda e: e.value) if version < 9 else (lambda e: e.name.lower())
    time = lambda t: {"sec": t.sec, "nsec": t.nsec}
    return {"history": enum(q.history), "depth": q.depth, "reliability": enum(q.reliability),
            "durability": enum(q.durability), "deadline": time(q.deadline),
            "lifespan": time(q.lifespan), "liveliness": enum(q.liveliness),
            "liveliness_lease_duration": time(q.liveliness_lease_duration),
            "avoid_ros_namespace_conventions": q.avoid_ros_namespace_conventions}


def rosbag2_metadata(version: int, storage: str, files, bag: Bag, counts, distro: str,
                     compression=("", "")) -> str:
    """metadata.yaml as rosbag2 writes it at `version` (4..9): its fields, in
    its order, nothing a version does not have."""
    def topic(t: Topic):
        qos = [qos_fields(q, version) for q in t.qos]
        d = {"name": t.name, "type": t.msgtype, "serialization_format": t.serialization_format,
             "offered_qos_profiles": qos if version >= 9 else emit(qos, 0)}
        if version >= 7:
            d["type_description_hash"] = t.digest
        return d

    start = min(f.start for f in files)
    end = max(f.start + f.duration for f in files)
    info = {"version": version, "storage_identifier": storage}
    if version == 4:
        info["relative_file_paths"] = [f.path for f in files]
    info["duration"] = {"nanoseconds": end - start}
    info["starting_time"] = {"nanoseconds_since_epoch": start}
    info["message_count"] = sum(f.count for f in files)
    info["topics_with_message_count"] = [{"topic_metadata": topic(t), "message_count": c}
                                         for t, c in zip(bag.topics, counts)]
    info["compression_format"], info["compression_mode"] = compression
    if version >= 5:
        info["relative_file_paths"] = [f.path for f in files]
        info["files"] = [{"path": f.path, "starting_time": {"nanoseconds_since_epoch": f.start},
                          "duration": {"nanoseconds": f.duration}, "message_count": f.count}
                         for f in files]
    if version >= 6:
        info["custom_data"] = None
    if version >= 8:
        info["ros_distro"] = distro
    return emit({"rosbag2_bagfile_information": info}, 0)


def emit(node, indent: int) -> str:
    """Block YAML as yaml-cpp emits it: two-space indents, sequences two in
    from their key, no trailing newline."""
    pad = " " * indent
    if isinstance(node, dict):
        lines = []
        for k, v in node.items():
            if isinstance(v, (dict, list)) and v:
                lines.append(f"{pad}{k}:\n{emit(v, indent + 2)}")
            else:
                lines.append(f"{pad}{k}: {scalar(v)}")
        return "\n".join(lines)
    if isinstance(node, list):
        if not node:
            return "[]"
        return "\n".join(f"{pad}- " + emit(v, indent + 2).lstrip(" ") if isinstance(v, dict)
                         else f"{pad}- {scalar(v)}" for v in node)
    return scalar(node)


def scalar(v) -> str:
    if v is None or v == {}:
        return "~"
    if v == []:
        return "[]"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if plain_ok(v):
        return v
    out = []
    for ch in v:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ch == "\n":
            out.append("\\n")
        elif ch == "\t":
            out.append("\\t")
        elif ord(ch) < 0x20:
            out.append(f"\\x{ord(ch):02x}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def plain_ok(s: str) -> bool:
    """Whether yaml-cpp writes the string unquoted."""
    if not s or s != s.strip() or s[0] in "-?:,[]{}#&*!|>'\"%@`":
        return False
    if s.lower() in ("~", "null", "true", "false", "yes", "no", "on", "off", "y", "n"):
        return False
    if ": " in s or " #" in s or s.endswith(":"):
        return False
    return all(ord(ch) >= 0x20 for ch in s)


# --- .db3 files of older rosbag2 releases ------------------------------

def write_old_sqlite(path: Path, bag: Bag, tables, pragmas, schema_row=None):
    conn = sqlite3.connect(path)
    for p in pragmas:
        conn.execute(p).fetchall()
    for stmt in tables:
        conn.execute(stmt)
    if schema_row:
        conn.execute("INSERT INTO schema (schema_version, ros_distro) VALUES (?, ?)", schema_row)
    for t in bag.topics:
        conn.execute("INSERT INTO topics (name, type, serialization_format, offered_qos_profiles) "
                     "VALUES (?, ?, ?, ?)",
                     (t.name, t.msgtype, t.serialization_format,
                      emit([qos_fields(q, 8) for q in t.qos], 0)))
    conn.executemany("INSERT INTO messages (timestamp, topic_id, data) VALUES (?, ?, ?)",
                     ((t, i + 1, raw) for i, t, raw in bag.messages))
    conn.commit()
    conn.close()


def whole_file(bag: Bag, name: str) -> FileInfo:
    t0, t1 = bag.messages[0][1], bag.messages[-1][1]
    return FileInfo(name, t0, t1 - t0, len(bag.messages))


def counts(bag: Bag):
    c = [0] * len(bag.topics)
    for i, _, _ in bag.messages:
        c[i] += 1
    return c


def main():
    ap = argparse.ArgumentParser(description="Write a rosbag2 recording in many storage layouts.")
    ap.add_argument("in_bag", type=Path)
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--force", action="store_true", help="replace variants that exist")
    a = ap.parse_args()
    bag = read_bag(a.in_bag)
    if not bag.messages:
        raise SystemExit(f"{a.in_bag}: no messages")
    out = a.out_dir
    out.mkdir(parents=True, exist_ok=True)

    def fresh(name: str) -> Path:
        d = out / name
        if d.exists():
            if not a.force:
                raise SystemExit(f"{d} exists (--force replaces it)")
            shutil.rmtree(d)
        return d

    def done(name: str, what: str):
        files = sorted(p.name for p in (out / name).iterdir())
        print(f"{name}: {what} [{', '.join(files)}]")

    for storage in ("sqlite3", "mcap"):
        for version in (8, 9):
            name = f"{storage}_v{version}"
            write_rosbags(fresh(name), bag, bag.messages, storage, version)
            done(name, f"rosbags, {storage}, metadata v{version}")
    for storage in ("sqlite3", "mcap"):
        name = f"{storage}_file_zstd"
        write_rosbags(fresh(name), bag, bag.messages, storage, 9, CompressionMode.FILE)
        done(name, f"rosbags, {storage}, file compression zstd, metadata v9")
    name = "sqlite3_message_zstd"
    write_rosbags(fresh(name), bag, bag.messages, "sqlite3", 9, CompressionMode.MESSAGE)
    done(name, "rosbags, sqlite3, message compression zstd, metadata v9")
    for storage in ("sqlite3", "mcap"):
        for suffix, with_metadata in (("split", True), ("split_no_metadata", False)):
            name = f"{storage}_{suffix}"
            write_split(fresh(name), bag, storage, with_metadata)
            done(name, f"rosbags, {storage}, {SPLIT_PARTS} files by time, "
                       + ("merged metadata v9" if with_metadata else "no metadata.yaml"))
    c = counts(bag)
    for storage, versions in (("sqlite3", (4, 5, 6, 7)), ("mcap", (5, 7))):
        src = next(p for p in (out / f"{storage}_v8").iterdir() if p.name != "metadata.yaml")
        for version in versions:
            name = f"{storage}_v{version}"
            d = fresh(name)
            d.mkdir()
            file = f"{name}_0.{EXT[storage]}"
            shutil.copyfile(src, d / file)
            (d / "metadata.yaml").write_text(
                rosbag2_metadata(version, storage, [whole_file(bag, file)], bag, c, bag.distro))
            done(name, f"rosbags' v8 {storage} file, rosbag2's metadata v{version} layout")
    for name, tables, pragmas, schema_row, version in (
            ("sqlite3_foxy", FOXY_TABLES, ["PRAGMA journal_mode = WAL;", "PRAGMA synchronous = NORMAL;"],
             None, 4),
            ("sqlite3_humble", HUMBLE_TABLES, ["PRAGMA journal_mode=MEMORY;", "PRAGMA synchronous=OFF;"],
             (3, "humble"), 5)):
        d = fresh(name)
        d.mkdir()
        file = f"{name}_0.db3"
        write_old_sqlite(d / file, bag, tables, pragmas, schema_row)
        (d / "metadata.yaml").write_text(
            rosbag2_metadata(version, "sqlite3", [whole_file(bag, file)], bag, c, bag.distro))
        done(name, f"sqlite3 module, {name.split('_')[1]} .db3 tables, metadata v{version}")


if __name__ == "__main__":
    main()
