"""Bags of fourws runs: rosbag2 layout (``metadata.yaml`` + one MCAP file), read, recover.

Layout written by :class:`BagWriter` (the recorder node's storage), the same as rosbag2's
MCAP storage plugin writes on Jazzy, so ``rosbags`` and the MCAP tools read it::

    <bag>/metadata.yaml        rosbag2_bagfile_information, version 9
    <bag>/<bag>_0.mcap         profile ros2; schemas ros2msg; channels cdr; zstd chunks

Schemas carry the full ``ros2msg`` text: the type's own ``.msg`` file, then for every type
it depends on (recursively, each once) a line of 80 ``=``, ``MSG: pkg/Type`` and that type's
``.msg`` text, read from the installed share folders (ament index). Channels carry
``offered_qos_profiles`` (YAML text) and ``topic_type_hash`` (RIHS01 from the type's
installed ``.json`` type description). A message's ``log_time`` is the wall time it was
received; its ``publish_time`` is its header stamp (or ``builtin_interfaces/Time`` first
field, as in ``/clock``) read straight from the CDR bytes, otherwise the receive time.

:func:`read_run` decodes a run into per-topic numpy arrays, :func:`recover` rewrites the
complete chunks of a truncated file as a whole file, :func:`recover_folder` does that in
place in a bag folder and rewrites its metadata.yaml. Every problem with a file is a
:class:`BagError` whose message names the file and what is wrong.

No rclpy here: only mcap, mcap_ros2, numpy, yaml and (for schema text) ament_index_python.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import re
import struct
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

MCAP_MAGIC = b"\x89MCAP0\r\n"
FOOTER_RECORD_LEN = 1 + 8 + 20  # opcode, length, summary_start, summary_offset_start, crc
DELIMITER = "=" * 80
ROSBAG2_VERSION = 9
ROS_DISTRO = "jazzy"
INFINITE_DURATION = {"sec": 9223372036, "nsec": 854775807}  # RMW_DURATION_INFINITE
#: libyaml's emitter when PyYAML has it (same text, ~5x faster: metadata.yaml is rewritten
#: after every chunk by the recorder), else the pure-Python one.
_YAML_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


class BagError(Exception):
    """A bag or MCAP file that cannot be written, read or recovered; the message names it."""


# ---------------------------------------------------------------------------------------------
# Topics of the fourws graph and their QoS (design.md); fourws_common.qos holds the profiles.
# ---------------------------------------------------------------------------------------------
QOS_KINDS: dict[str, dict[str, Any]] = {
    "control": {"history": "keep_last", "depth": 1000, "reliability": "reliable",
                "durability": "volatile"},
    "latched": {"history": "keep_last", "depth": 1, "reliability": "reliable",
                "durability": "transient_local"},
    "clock": {"history": "keep_last", "depth": 1000, "reliability": "reliable",
              "durability": "volatile"},
    "diagnostics": {"history": "keep_last", "depth": 10, "reliability": "reliable",
                    "durability": "volatile"},
}

TOPICS: dict[str, tuple[str, str]] = {
    "/clock": ("rosgraph_msgs/msg/Clock", "clock"),
    "/vehicle/state": ("fourws_msgs/msg/VehicleState", "control"),
    "/vehicle/odom": ("nav_msgs/msg/Odometry", "control"),
    "/reference/trajectory": ("fourws_msgs/msg/ReferenceTrajectory", "latched"),
    "/reference/path": ("nav_msgs/msg/Path", "latched"),
    "/control/mpc_command": ("fourws_msgs/msg/MpcCommand", "control"),
    "/control/mpc_diagnostics": ("fourws_msgs/msg/MpcDiagnostics", "control"),
    "/control/drive_command": ("fourws_msgs/msg/DriveCommand", "control"),
    "/control/wheel_torques": ("fourws_msgs/msg/WheelTorques", "control"),
    "/run/status": ("std_msgs/msg/String", "latched"),
    "/diagnostics": ("diagnostic_msgs/msg/DiagnosticArray", "diagnostics"),
}
DEFAULT_TOPICS: tuple[str, ...] = tuple(TOPICS)


@dataclass(frozen=True)
class TopicInfo:
    """One recorded topic: name, ROS type (``pkg/msg/Type``) and the QoS it is offered with."""

    name: str
    type: str
    qos: Mapping[str, Any] = field(default_factory=lambda: dict(QOS_KINDS["control"]))


def topic_info(spec: str) -> TopicInfo:
    """A topic of the graph by name, or ``/name:pkg/msg/Type`` for any other topic.

    Raises ``ValueError`` naming the topic when its type is not known.
    """
    name, _, typ = spec.partition(":")
    name = name.strip()
    if typ:
        typ = normalise_type(typ.strip())
        kind = TOPICS[name][1] if name in TOPICS else "control"
        return TopicInfo(name, typ, dict(QOS_KINDS[kind]))
    if name not in TOPICS:
        raise ValueError(f"topics: unknown topic '{name}' (known: {', '.join(TOPICS)}; "
                         "give others as '/name:pkg/msg/Type')")
    typ, kind = TOPICS[name]
    return TopicInfo(name, typ, dict(QOS_KINDS[kind]))


def normalise_type(type_name: str) -> str:
    """``pkg/Type`` or ``pkg/msg/Type`` -> ``pkg/msg/Type``."""
    parts = type_name.strip().split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    if len(parts) == 3 and parts[1] == "msg":
        return type_name.strip()
    raise ValueError(f"not a message type name: '{type_name}' (expected pkg/msg/Type)")


# ---------------------------------------------------------------------------------------------
# Schema text (ros2msg, rosbag2 style) and type hashes from the installed interface files
# ---------------------------------------------------------------------------------------------
PRIMITIVES = frozenset({
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
})
_FIELD_TYPE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_/]*)")


def _share_dir(package: str) -> Path:
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

    try:
        return Path(get_package_share_directory(package))
    except PackageNotFoundError as exc:
        raise BagError(f"interface package '{package}' is not installed (ament index: "
                       f"{os.environ.get('AMENT_PREFIX_PATH', '')!r}); source ros_ws/env.sh"
                       ) from exc


def msg_file(type_name: str) -> Path:
    """The installed ``.msg`` file of ``pkg/msg/Type`` (via the ament index)."""
    pkg, _, name = normalise_type(type_name).split("/")
    path = _share_dir(pkg) / "msg" / f"{name}.msg"
    if not path.is_file():
        raise BagError(f"no message definition {path} for {type_name}")
    return path


def msg_dependencies(text: str, package: str) -> list[str]:
    """Types (``pkg/Type``) used by the fields of a ``.msg`` text, in order of first use.

    Constants and primitives are skipped; a bare ``Type`` means ``package/Type`` (``Header``
    alone means ``std_msgs/Header``, as rosidl reads it).
    """
    deps: list[str] = []
    for line in text.splitlines():
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        m = _FIELD_TYPE.match(stripped)
        if not m:
            continue
        base = m.group(1)
        if base in PRIMITIVES:
            continue
        if "/" in base:
            parts = base.split("/")
            dep = f"{parts[0]}/{parts[-1]}"
        elif base == "Header":
            dep = "std_msgs/Header"
        else:
            dep = f"{package}/{base}"
        if dep not in deps:
            deps.append(dep)
    return deps


def message_definition(type_name: str) -> str:
    """Full ``ros2msg`` schema text of a type, as rosbag2 stores it in MCAP.

    The type's ``.msg`` text, then for each dependency (depth first, each once) a line of
    80 ``=``, ``MSG: pkg/Type`` and the dependency's ``.msg`` text.
    """
    top = normalise_type(type_name)
    top_pkg = top.split("/")[0]
    text = msg_file(top).read_text(encoding="utf-8")
    parts = [text.rstrip("\n")]
    seen: set[str] = set()

    def visit(body: str, pkg: str) -> None:
        for dep in msg_dependencies(body, pkg):
            if dep in seen:
                continue
            seen.add(dep)
            dpkg, dname = dep.split("/")
            dtext = msg_file(f"{dpkg}/msg/{dname}").read_text(encoding="utf-8")
            parts.append(f"{DELIMITER}\nMSG: {dep}\n{dtext.rstrip(chr(10))}")
            visit(dtext, dpkg)

    visit(text, top_pkg)
    return "\n".join(parts) + "\n"


def type_hash(type_name: str) -> str:
    """RIHS01 type hash of ``pkg/msg/Type`` from its installed ``.json`` (``""`` if none)."""
    top = normalise_type(type_name)
    path = msg_file(top).with_suffix(".json")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return ""
    for entry in data.get("type_hashes", []):
        if entry.get("type_name") == top:
            return str(entry.get("hash_string", ""))
    return ""


def first_field_is_stamp(definition: str) -> bool:
    """True if the message's first field is a ``std_msgs/Header`` or a ``builtin_interfaces/Time``
    (its CDR bytes then start with the stamp: see :func:`cdr_stamp_ns`)."""
    for line in definition.splitlines():
        s = line.strip()
        if s.startswith(DELIMITER):
            return False
        if not s or s.startswith("#"):
            continue
        m = _FIELD_TYPE.match(s)
        if not m or "=" in s.split("#")[0]:
            continue  # a constant is not a field
        return m.group(1) in ("std_msgs/Header", "std_msgs/msg/Header", "Header",
                              "builtin_interfaces/Time", "builtin_interfaces/msg/Time")
    return False


def cdr_stamp_ns(data: bytes | memoryview) -> int | None:
    """Stamp (ns) of a serialized message whose first field is a Header or a Time.

    CDR: 4 bytes of encapsulation (representation 0x0000 big, 0x0001 little endian), then
    ``int32 sec`` and ``uint32 nanosec``. ``None`` if the bytes are too short.
    """
    if len(data) < 12:
        return None
    rep = bytes(data[0:2])
    fmt = "<iI" if rep in (b"\x00\x01", b"\x00\x03") else ">iI"
    sec, nsec = struct.unpack_from(fmt, data, 4)
    return sec * 1_000_000_000 + nsec


# ---------------------------------------------------------------------------------------------
# QoS text as rosbag2 writes it
# ---------------------------------------------------------------------------------------------
def qos_profile_dict(qos: Mapping[str, Any]) -> dict[str, Any]:
    """A full rosbag2 (version 9) QoS entry from ``history, depth, reliability, durability``."""
    return {
        "history": str(qos.get("history", "keep_last")),
        "depth": int(qos.get("depth", 10)),
        "reliability": str(qos.get("reliability", "reliable")),
        "durability": str(qos.get("durability", "volatile")),
        "deadline": dict(INFINITE_DURATION),
        "lifespan": dict(INFINITE_DURATION),
        "liveliness": str(qos.get("liveliness", "automatic")),
        "liveliness_lease_duration": dict(INFINITE_DURATION),
        "avoid_ros_namespace_conventions": False,
    }


def qos_yaml(qos: Mapping[str, Any]) -> str:
    """The ``offered_qos_profiles`` channel metadata: a YAML list of one profile."""
    return yaml.safe_dump([qos_profile_dict(qos)], sort_keys=False,
                          default_flow_style=False).strip()


def parse_offered_qos(text: str) -> dict[str, Any] | None:
    """First profile of an ``offered_qos_profiles`` YAML text (names or rosbag2 v8 integers)."""
    try:
        items = yaml.safe_load(text) if isinstance(text, str) else text
    except yaml.YAMLError:
        return None
    if not isinstance(items, list) or not items or not isinstance(items[0], dict):
        return None
    item = items[0]
    ints = {"history": {1: "keep_last", 2: "keep_all"},
            "reliability": {1: "reliable", 2: "best_effort"},
            "durability": {1: "transient_local", 2: "volatile"}}
    out: dict[str, Any] = {"depth": int(item.get("depth", 10) or 10)}
    defaults = {"history": "keep_last", "reliability": "reliable", "durability": "volatile"}
    for key, table in ints.items():
        v = item.get(key, defaults[key])
        v = table.get(v, defaults[key]) if isinstance(v, int) else str(v).lower()
        out[key] = v if v in table.values() else defaults[key]
    return out


# ---------------------------------------------------------------------------------------------
# metadata.yaml
# ---------------------------------------------------------------------------------------------
@dataclass
class TopicRecord:
    """A topic as listed in metadata.yaml."""

    info: TopicInfo
    message_count: int = 0
    type_description_hash: str = ""


def write_metadata(folder: str | Path, *, relative_file_paths: list[str],
                   topics: Iterable[TopicRecord], starting_time_ns: int, duration_ns: int,
                   custom_data: Mapping[str, str] | None = None) -> Path:
    """Write ``folder/metadata.yaml`` (rosbag2 version 9, storage mcap) atomically.

    ``compression_format``/``compression_mode`` stay empty: the MCAP chunks are compressed
    inside the storage, which rosbag2 does not list as bag compression.
    """
    folder = Path(folder)
    topics = list(topics)
    info = build_metadata(relative_file_paths=relative_file_paths, topics=topics,
                          starting_time_ns=starting_time_ns, duration_ns=duration_ns,
                          custom_data=custom_data)
    text = yaml.dump({"rosbag2_bagfile_information": info}, Dumper=_YAML_DUMPER,
                     sort_keys=False, default_flow_style=False)
    path = folder / "metadata.yaml"
    tmp = folder / ".metadata.yaml.tmp"
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return path


def build_metadata(*, relative_file_paths: list[str], topics: list[TopicRecord],
                   starting_time_ns: int, duration_ns: int,
                   custom_data: Mapping[str, str] | None = None) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping (see :func:`write_metadata`)."""
    total = sum(t.message_count for t in topics)
    start = int(starting_time_ns) if total else 0
    duration = int(max(0, duration_ns)) if total else 0
    return {
        "version": ROSBAG2_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": total,
        "topics_with_message_count": [
            {"topic_metadata": {
                "name": t.info.name,
                "type": t.info.type,
                "serialization_format": "cdr",
                "offered_qos_profiles": [qos_profile_dict(t.info.qos)],
                "type_description_hash": t.type_description_hash,
            }, "message_count": int(t.message_count)}
            for t in topics
        ],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": list(relative_file_paths),
        "files": [{"path": p, "starting_time": {"nanoseconds_since_epoch": start},
                   "duration": {"nanoseconds": duration}, "message_count": total}
                  for p in relative_file_paths],
        "custom_data": dict(custom_data) if custom_data else None,
        "ros_distro": ROS_DISTRO,
    }


# ---------------------------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------------------------
def _compression(name: str):
    from mcap.writer import CompressionType

    table = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
             "none": CompressionType.NONE, "": CompressionType.NONE}
    if name not in table:
        raise ValueError(f"compression: '{name}' is not one of zstd, lz4, none")
    return table[name]


class BagWriter:
    """Write serialized messages into a rosbag2-layout MCAP bag, chunk by chunk.

    ``folder`` must not exist or be empty. ``metadata.yaml`` is written at once (zero
    counts, ``custom_data.fourws_state: recording``), again after every completed chunk (the
    counts that are on disk), and finally by :meth:`close` (``complete``). After every
    completed chunk the file is flushed to the OS, so a killed process loses at most the
    chunk that was open. :meth:`close` is idempotent.
    """

    def __init__(self, folder: str | Path, topics: Iterable[TopicInfo], *,
                 chunk_size_bytes: int = 262144, compression: str = "zstd",
                 library: str = "fourws recorder") -> None:
        from mcap.writer import LIBRARY_IDENTIFIER, Writer

        self.folder = Path(folder)
        if self.folder.exists() and (not self.folder.is_dir() or any(self.folder.iterdir())):
            raise ValueError(f"output_dir: {self.folder} exists and is not an empty folder")
        self.folder.mkdir(parents=True, exist_ok=True)
        self.file_name = f"{self.folder.name}_0.mcap"
        self.path = self.folder / self.file_name
        self._fh = open(self.path, "xb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._fh, chunk_size=int(chunk_size_bytes),
                              compression=_compression(compression))
        self._writer.start(profile="ros2", library=f"{library}; {LIBRARY_IDENTIFIER}")
        self.compression = compression
        self.records: dict[str, TopicRecord] = {}
        self._channels: dict[str, int] = {}
        self._stamped: dict[str, bool] = {}
        self._schemas: dict[str, int] = {}
        self._seq: dict[str, int] = {}
        self._first_ns: int | None = None
        self._last_ns = 0
        self._durable: tuple[dict[str, int], int | None, int] = ({}, None, 0)
        self._pos = self._fh.tell()
        self.closed = False
        self.chunks_written = 0
        for t in topics:
            self.add_topic(t)
        self._write_metadata(durable=True, state="recording")

    def add_topic(self, info: TopicInfo) -> None:
        """Register a topic (schema once per type, one channel per topic)."""
        if info.name in self._channels:
            return
        definition = message_definition(info.type)
        if info.type not in self._schemas:
            self._schemas[info.type] = self._writer.register_schema(
                name=info.type, encoding="ros2msg", data=definition.encode("utf-8"))
        digest = type_hash(info.type)
        meta = {"offered_qos_profiles": qos_yaml(info.qos)}
        if digest:
            meta["topic_type_hash"] = digest
        self._channels[info.name] = self._writer.register_channel(
            topic=info.name, message_encoding="cdr", schema_id=self._schemas[info.type],
            metadata=meta)
        self._stamped[info.name] = first_field_is_stamp(definition)
        self.records[info.name] = TopicRecord(info, 0, digest)
        self._seq[info.name] = 0

    def stamped(self, topic: str) -> bool:
        """Whether the topic's messages start with a stamp (used for publish_time)."""
        return self._stamped[topic]

    def write(self, topic: str, data: bytes, log_time_ns: int,
              publish_time_ns: int | None = None) -> bool:
        """Append one serialized message. Returns True when a chunk was completed (and flushed).

        ``publish_time_ns`` defaults to the message's stamp if it has one, else ``log_time_ns``.
        """
        if self.closed:
            raise BagError(f"{self.path}: write after close")
        if publish_time_ns is None:
            stamp = cdr_stamp_ns(data) if self._stamped[topic] else None
            publish_time_ns = log_time_ns if stamp is None or stamp < 0 else stamp
        self._seq[topic] += 1
        self._writer.add_message(channel_id=self._channels[topic], log_time=int(log_time_ns),
                                 data=bytes(data), publish_time=int(publish_time_ns),
                                 sequence=self._seq[topic] & 0xFFFFFFFF)
        self.records[topic].message_count += 1
        self._first_ns = log_time_ns if self._first_ns is None else min(self._first_ns,
                                                                         log_time_ns)
        self._last_ns = max(self._last_ns, log_time_ns)
        pos = self._fh.tell()
        if pos == self._pos:
            return False
        self._pos = pos
        self._fh.flush()
        self.chunks_written += 1
        self._durable = ({k: r.message_count for k, r in self.records.items()},
                         self._first_ns, self._last_ns)
        self._write_metadata(durable=True, state="recording")
        return True

    @property
    def message_count(self) -> int:
        return sum(r.message_count for r in self.records.values())

    def _write_metadata(self, *, durable: bool, state: str) -> None:
        if durable:
            counts, first, last = self._durable
        else:
            counts = {k: r.message_count for k, r in self.records.items()}
            first, last = self._first_ns, self._last_ns
        topics = [dataclasses.replace(r, message_count=counts.get(k, 0))
                  for k, r in self.records.items()]
        write_metadata(self.folder, relative_file_paths=[self.file_name], topics=topics,
                       starting_time_ns=first or 0, duration_ns=(last - first) if first else 0,
                       custom_data={"fourws_state": state,
                                    "fourws_chunk_compression": self.compression})

    def close(self) -> None:
        """Finish the MCAP file (last chunk, summary, footer) and write final metadata.yaml."""
        if self.closed:
            return
        self.closed = True
        counts = {k: r.message_count for k, r in self.records.items()}
        first, last = self._first_ns, self._last_ns
        topics = [dataclasses.replace(r, message_count=counts[k]) for k, r in self.records.items()]
        info = build_metadata(relative_file_paths=[self.file_name], topics=topics,
                              starting_time_ns=first or 0,
                              duration_ns=(last - first) if first else 0)
        self._writer.add_metadata("rosbag2", {"serialized_metadata": yaml.safe_dump(
            info, sort_keys=False, default_flow_style=False)})
        self._writer.finish()
        self._fh.flush()
        with contextlib.suppress(OSError):
            os.fsync(self._fh.fileno())
        self._fh.close()
        self._write_metadata(durable=False, state="complete")


# ---------------------------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------------------------
def _size_text(n: int) -> str:
    if n >= 1_000_000:
        return f"{n / 1e6:.1f} MB"
    if n >= 1000:
        return f"{n / 1e3:.1f} kB"
    return f"{n} bytes"


def resolve_mcap(path: str | Path) -> Path:
    """The MCAP file of a run folder (``bag/`` inside), a bag folder or a bare ``.mcap``."""
    p = Path(path)
    if p.is_file():
        return p
    if not p.exists():
        raise BagError(f"{p}: no such bag, run folder or MCAP file")
    if (p / "bag").is_dir() and not (p / "metadata.yaml").is_file():
        p = p / "bag"
    meta = p / "metadata.yaml"
    if meta.is_file():
        try:
            info = (yaml.safe_load(meta.read_text(encoding="utf-8")) or {}).get(
                "rosbag2_bagfile_information", {})
            files = [p / Path(f).name for f in info.get("relative_file_paths", [])]
        except (yaml.YAMLError, AttributeError) as exc:
            raise BagError(f"{meta}: not a rosbag2 metadata file: {exc}") from exc
        files = [f for f in files if f.suffix == ".mcap"]
        if files:
            if not files[0].is_file():
                raise BagError(f"{meta}: lists {files[0].name}, which does not exist")
            return files[0]
    found = sorted(p.glob("*.mcap"))
    if not found:
        raise BagError(f"{p}: no .mcap file in this folder")
    return found[0]


def check_mcap(path: Path) -> None:
    """Raise :class:`BagError` unless the file starts and ends like a finished MCAP file."""
    try:
        size = path.stat().st_size
        with open(path, "rb") as fh:
            head = fh.read(8)
            if size >= 8 + FOOTER_RECORD_LEN + 8:
                fh.seek(size - FOOTER_RECORD_LEN - 8)
                tail = fh.read(FOOTER_RECORD_LEN + 8)
            else:
                tail = b""
    except OSError as exc:
        raise BagError(f"{path}: cannot read: {exc.strerror}") from exc
    if size == 0:
        raise BagError(f"{path}: empty file (the recorder wrote nothing)")
    if head != MCAP_MAGIC:
        if len(head) < 8 and head == MCAP_MAGIC[:len(head)]:
            raise BagError(f"{path}: truncated after {_size_text(size)} (no MCAP header)")
        raise BagError(f"{path}: not an MCAP file (bad magic)")
    if not (tail.endswith(MCAP_MAGIC) and tail[0] == 0x02
            and struct.unpack_from("<Q", tail, 1)[0] == 20):
        raise BagError(f"{path}: truncated after {_size_text(size)} (no footer); run "
                       f"'fourws bag recover {path}'")


def _read_errors() -> tuple[type[BaseException], ...]:
    from mcap.exceptions import McapError

    errs: list[type[BaseException]] = [McapError, struct.error, ValueError, EOFError,
                                       UnicodeDecodeError, KeyError, IndexError]
    with contextlib.suppress(ImportError):
        import zstandard

        errs.append(zstandard.ZstdError)
    return tuple(errs)


@dataclass
class ChannelInfo:
    """A channel of an MCAP file: topic, type, schema text, offered QoS, message count."""

    topic: str
    type: str
    definition: str
    qos: dict[str, Any] | None
    message_count: int


class McapBag:
    """A finished MCAP file opened for reading (``with McapBag(path) as bag: ...``)."""

    def __init__(self, path: str | Path) -> None:
        self.path = resolve_mcap(path)
        check_mcap(self.path)
        from mcap.reader import SeekingReader

        self._fh = open(self.path, "rb")  # noqa: SIM115 - closed in close()
        try:
            self._reader = SeekingReader(self._fh, validate_crcs=True)
            summary = self._reader.get_summary()
        except _read_errors() as exc:
            self._fh.close()
            raise BagError(f"{self.path}: corrupt MCAP summary: {exc}") from exc
        if summary is None:
            self._fh.close()
            raise BagError(f"{self.path}: MCAP file without a summary section")
        self.summary = summary
        counts = summary.statistics.channel_message_counts if summary.statistics else {}
        self.channels: dict[str, ChannelInfo] = {}
        for cid, ch in summary.channels.items():
            schema = summary.schemas.get(ch.schema_id)
            self.channels[ch.topic] = ChannelInfo(
                ch.topic, schema.name if schema else "",
                schema.data.decode("utf-8", "replace") if schema else "",
                parse_offered_qos(ch.metadata.get("offered_qos_profiles", "")),
                int(counts.get(cid, 0)))

    def __enter__(self) -> McapBag:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._fh.close()

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[tuple[str, int, int,
                                                                              bytes]]:
        """``(topic, log_time_ns, publish_time_ns, data)`` in log-time (recorded) order."""
        topics = None if topics is None else list(topics)
        try:
            for _schema, channel, msg in self._reader.iter_messages(topics=topics,
                                                                    log_time_order=True):
                yield channel.topic, msg.log_time, msg.publish_time, msg.data
        except _read_errors() as exc:
            raise BagError(f"{self.path}: corrupt data: {exc}") from exc

    def decoded(self, topics: Iterable[str] | None = None) -> Iterator[tuple[str, int, Any]]:
        """``(topic, log_time_ns, message)`` decoded with mcap_ros2's CDR decoder."""
        from mcap_ros2.decoder import DecoderFactory

        factory = DecoderFactory()
        decoders: dict[int, Any] = {}
        topics = None if topics is None else list(topics)
        try:
            for schema, channel, msg in self._reader.iter_messages(topics=topics,
                                                                   log_time_order=True):
                dec = decoders.get(channel.id)
                if dec is None:
                    dec = factory.decoder_for(channel.message_encoding, schema)
                    if dec is None:
                        raise BagError(f"{self.path}: no decoder for {channel.topic} "
                                       f"({channel.message_encoding}, schema "
                                       f"{schema.encoding if schema else 'none'})")
                    decoders[channel.id] = dec
                try:
                    value = dec(msg.data)
                except _read_errors() as exc:
                    raise BagError(f"{self.path}: cannot decode a message on {channel.topic} "
                                   f"at log time {msg.log_time}: {exc}") from exc
                yield channel.topic, msg.log_time, value
        except BagError:
            raise
        except _read_errors() as exc:
            raise BagError(f"{self.path}: corrupt data: {exc}") from exc


def _fields(msg: Any) -> list[str]:
    return [f for f in getattr(msg, "__slots__", ()) if f != "header"]


def _stamp_of(msg: Any) -> int | None:
    header = getattr(msg, "header", None)
    if header is None:
        return None
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _column(values: list[Any]) -> np.ndarray:
    if values and isinstance(values[0], str):
        return np.array(values, dtype=object)
    if values and isinstance(values[0], list | tuple | np.ndarray | bytes):
        try:
            return np.array([np.asarray(v, dtype=float) for v in values], dtype=float)
        except ValueError:
            return np.array(values, dtype=object)
    if values and isinstance(values[0], bool):
        return np.array(values, dtype=bool)
    return np.array(values, dtype=float)


def drop_strays(stamped: list[tuple[int, int, Any]]) -> tuple[list[tuple[int, int, Any]], int]:
    """The messages of one per-step topic that lie on the run's timeline, in receive order,
    and how many did not: the nodes' own stamp rule
    (:class:`fourws_common.input_guard.StampGate`), so a stray stamped 1e6 s ahead (or in the
    past) that every controller rejected is not a step of the run either, and the analysis
    grid does not stretch to it. A message less than the jump limit behind the timeline is
    kept: it only arrived late."""
    from fourws_common.input_guard import MAX_STAMP_JUMP_NS, Stamp, StampGate

    gate = StampGate(MAX_STAMP_JUMP_NS)
    kept = []
    for row in stamped:
        verdict = gate.check(row[0])
        if verdict is Stamp.FUTURE:
            continue
        if verdict is Stamp.PAST and gate.last_ns - row[0] > MAX_STAMP_JUMP_NS:
            continue  # a late arrival within the window is kept (rows are sorted by stamp)
        kept.append(row)
    return kept, len(stamped) - len(kept)


def _columns(stamped: list[tuple[int, int, Any]]) -> dict[str, np.ndarray]:
    """Per-step columns from ``(stamp_ns, log_time_ns, msg)``: the first message of each
    stamp, sorted by stamp; ``log_ns`` is when the recorder received it."""
    first: dict[int, tuple[int, Any]] = {}
    for stamp, log_ns, msg in stamped:
        if stamp not in first:
            first[stamp] = (log_ns, msg)
    stamps = sorted(first)
    out: dict[str, np.ndarray] = {"stamp_ns": np.array(stamps, dtype=np.int64),
                                  "t_s": np.array(stamps, dtype=np.int64) * 1e-9,
                                  "log_ns": np.array([first[s][0] for s in stamps],
                                                     dtype=np.int64)}
    if not stamps:
        return out
    for name in _fields(first[stamps[0]][1]):
        out[name] = _column([getattr(first[s][1], name) for s in stamps])
    return out


STEP_TOPICS = {"/vehicle/state": "state", "/control/mpc_command": "mpc_command",
               "/control/mpc_diagnostics": "mpc_diagnostics",
               "/control/drive_command": "drive_command",
               "/control/wheel_torques": "wheel_torques"}


@dataclass
class RunData:
    """A recorded run as per-step numpy arrays (SI units, as on the wire).

    Each per-topic dict has ``stamp_ns`` (int64), ``t_s``, ``log_ns`` (int64, the recorder's
    receive time, wall clock) and one array per message field
    (scalars ``(n,)``, wheel arrays ``(n, 4)``, strings as object arrays), one row per header
    stamp (the first message of each stamp), sorted by stamp. A topic absent from the bag
    gives a dict with empty ``stamp_ns``/``t_s``/``log_ns`` only.
    """

    path: Path
    state: dict[str, np.ndarray]
    mpc_command: dict[str, np.ndarray]
    mpc_diagnostics: dict[str, np.ndarray]
    drive_command: dict[str, np.ndarray]
    wheel_torques: dict[str, np.ndarray]
    reference: dict[str, np.ndarray] | None
    status: dict[str, Any] | None
    message_counts: dict[str, int]
    #: Rejected inputs per node from /diagnostics: {node: {kind: count}}, the highest count
    #: each node reported (its counters only grow within a run).
    rejections: dict[str, dict[str, int]] = field(default_factory=dict)
    #: Messages per topic off the run's timeline (:func:`drop_strays`), left out above.
    strays: dict[str, int] = field(default_factory=dict)

    @property
    def steps(self) -> int:
        """Number of distinct VehicleState stamps."""
        return int(len(self.state["stamp_ns"]))

    @property
    def controller(self) -> str | None:
        """Controller name from the MPC diagnostics (the last one), if recorded."""
        c = self.mpc_diagnostics.get("controller")
        return str(c[-1]) if c is not None and len(c) else None

    @property
    def scenario(self) -> str | None:
        """Scenario name from /run/status, if recorded."""
        return None if not self.status else self.status.get("scenario")


def read_run(path: str | Path) -> RunData:
    """Decode a run folder (``bag/`` inside), a bag folder or a bare ``.mcap`` into arrays.

    Raises :class:`BagError` naming the file for a missing, truncated or corrupt bag.
    """
    with McapBag(path) as bag:
        counts = {t: c.message_count for t, c in bag.channels.items()}
        per: dict[str, list[tuple[int, Any]]] = {t: [] for t in STEP_TOPICS}
        reference = None
        status_text = None
        rejections: dict[str, dict[str, int]] = {}
        wanted = [t for t in (*STEP_TOPICS, "/reference/trajectory", "/run/status",
                              "/diagnostics") if t in bag.channels]
        for topic, log_ns, msg in bag.decoded(wanted):
            if topic in per:
                stamp = _stamp_of(msg)
                if stamp is not None:
                    per[topic].append((stamp, log_ns, msg))
            elif topic == "/reference/trajectory":
                reference = msg
            elif topic == "/run/status":
                status_text = msg.data
            elif topic == "/diagnostics":
                _add_rejections(rejections, msg)
        path_out = bag.path
    ref_arrays = None
    if reference is not None:
        ref_arrays = {name: np.asarray(getattr(reference, name), dtype=float)
                      for name in _fields(reference)}
        ref_arrays["stamp_ns"] = np.int64(_stamp_of(reference) or 0)
    status = None
    if status_text is not None:
        try:
            status = json.loads(status_text)
        except ValueError:
            status = {"raw": status_text}
    strays: dict[str, int] = {}
    for t in STEP_TOPICS:
        per[t], n = drop_strays(per[t])
        if n:
            strays[t] = n
    cols = {attr: _columns(per[t]) for t, attr in STEP_TOPICS.items()}
    return RunData(path=path_out, reference=ref_arrays, status=status,
                   message_counts=counts, rejections=rejections, strays=strays, **cols)


def _add_rejections(out: dict[str, dict[str, int]], msg: Any) -> None:
    """Fold one DiagnosticArray's counters (KeyValue value = a count) into ``out``."""
    for st in msg.status:
        node = out.setdefault(str(st.name).lstrip("/"), {})
        for kv in st.values:
            try:
                n = int(kv.value)
            except ValueError:
                continue
            node[kv.key] = max(n, node.get(kv.key, 0))


# ---------------------------------------------------------------------------------------------
# Recovery
# ---------------------------------------------------------------------------------------------
def recover(src: str | Path, dst: str | Path, *, compression: str = "zstd",
            chunk_size_bytes: int = 1024 * 1024) -> int:
    """Rewrite every complete record of a (truncated) MCAP file as a whole, valid file.

    Reads ``src`` front to back (non-seeking), keeps schemas, channels, metadata and the
    messages of every chunk that is complete and whose CRC checks, and stops cleanly at the
    first incomplete or damaged record. Returns the number of messages written to ``dst``.
    """
    from mcap.records import (
        Attachment,
        Channel,
        DataEnd,
        Footer,
        Header,
        Message,
        Metadata,
        Schema,
    )
    from mcap.stream_reader import StreamReader
    from mcap.writer import Writer

    src_path = resolve_mcap(src)
    dst_path = Path(dst)
    if dst_path.resolve() == src_path.resolve():
        raise BagError(f"{src_path}: recover needs another output file")
    with open(src_path, "rb") as fh:
        if fh.read(8) != MCAP_MAGIC:
            raise BagError(f"{src_path}: not an MCAP file (bad magic); nothing to recover")
        fh.seek(0)
        size = os.fstat(fh.fileno()).st_size
        records = StreamReader(fh, validate_crcs=True, record_size_limit=size).records
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        kept: list[Any] = []
        header = None
        errors = _read_errors()
        while True:
            try:
                rec = next(records)
            except StopIteration:
                break
            except errors:
                break  # the first incomplete or damaged record: keep what came before
            if isinstance(rec, Header):
                header = rec
            elif isinstance(rec, Schema):
                schemas.setdefault(rec.id, rec)
            elif isinstance(rec, Channel):
                channels.setdefault(rec.id, rec)
            elif isinstance(rec, Message | Attachment) or (
                    isinstance(rec, Metadata) and rec.name != "rosbag2"):
                kept.append(rec)
            elif isinstance(rec, DataEnd | Footer):
                break
    tmp = dst_path.with_name(dst_path.name + ".tmp")
    count = 0
    with open(tmp, "wb") as out:
        w = Writer(out, chunk_size=chunk_size_bytes, compression=_compression(compression))
        w.start(profile=header.profile if header else "ros2",
                library=(header.library if header else "unknown") + "; fourws recover")
        schema_ids = {sid: w.register_schema(s.name, s.encoding, s.data)
                      for sid, s in sorted(schemas.items())}
        channel_ids = {cid: w.register_channel(c.topic, c.message_encoding,
                                               schema_ids.get(c.schema_id, 0), c.metadata)
                       for cid, c in sorted(channels.items())}
        for rec in kept:
            if isinstance(rec, Message):
                if rec.channel_id not in channel_ids:
                    continue
                w.add_message(channel_ids[rec.channel_id], rec.log_time, rec.data,
                              rec.publish_time, rec.sequence)
                count += 1
            elif isinstance(rec, Metadata):
                w.add_metadata(rec.name, rec.metadata)
            elif isinstance(rec, Attachment):
                w.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type,
                                 rec.data)
        w.finish()
    os.replace(tmp, dst_path)
    return count


@dataclass(frozen=True)
class FolderRecovery:
    """What :func:`recover_folder` did: the bag's MCAP file (whole now), its rewritten
    metadata.yaml, the messages in the file, and where the cut file went (None: it was
    whole already and is untouched)."""

    mcap: Path
    metadata: Path
    messages: int
    kept_aside: Path | None


def in_bag_folder(path: str | Path) -> bool:
    """Whether ``path`` is a folder (a run or bag folder) or the ``.mcap`` of a bag folder
    (a metadata.yaml beside it): :func:`recover_folder` repairs those in place."""
    p = Path(path)
    return p.is_dir() or (p.suffix == ".mcap" and (p.parent / "metadata.yaml").is_file())


def _unused(path: Path) -> Path:
    """``path``, or ``path.1``, ``path.2``... whichever does not exist yet."""
    candidate, i = path, 0
    while candidate.exists():
        i += 1
        candidate = path.with_name(f"{path.name}.{i}")
    return candidate


def recover_folder(path: str | Path, *, compression: str = "zstd") -> FolderRecovery:
    """Repair a bag folder in place so every rosbag2 reader takes it whole.

    ``path`` is a run folder, a bag folder or the ``.mcap`` inside one. A truncated file is
    rewritten by :func:`recover` under its own name (so ``relative_file_paths`` stays
    right) and the cut original is moved aside to ``NAME.mcap.truncated`` (not listed in
    metadata.yaml, nothing lost). Then ``metadata.yaml`` is written from the file itself:
    per-topic message counts, types, offered QoS and type hashes from its channels,
    starting time and duration from its statistics; ``custom_data`` keeps what it held,
    with ``fourws_state: recovered`` (``complete`` for a file that was whole already) and
    ``fourws_recovered_from`` naming the cut file.
    """
    p = Path(path)
    mcap = p if p.is_file() else resolve_mcap(p)
    folder = mcap.parent
    try:
        check_mcap(mcap)
        kept = None
    except BagError:
        kept = _unused(mcap.with_name(mcap.name + ".truncated"))
        fixed = _unused(mcap.with_name(mcap.name + ".recovered"))
        recover(mcap, fixed, compression=compression)
        os.replace(mcap, kept)
        os.replace(fixed, mcap)
    meta_path = folder / "metadata.yaml"
    custom: dict[str, str] = {}
    with contextlib.suppress(OSError, yaml.YAMLError, AttributeError, TypeError):
        old = yaml.safe_load(meta_path.read_text(encoding="utf-8"))
        custom = {str(k): str(v) for k, v in
                  (old["rosbag2_bagfile_information"].get("custom_data") or {}).items()}
    custom["fourws_state"] = "complete" if kept is None else "recovered"
    if kept is not None:
        custom["fourws_recovered_from"] = kept.name
    with McapBag(mcap) as bag:
        summary = bag.summary
        stats = summary.statistics
        counts = stats.channel_message_counts if stats else {}
        topics = []
        for cid, ch in sorted(summary.channels.items()):
            schema = summary.schemas.get(ch.schema_id)
            typ = schema.name if schema else ""
            kind = TOPICS[ch.topic][1] if ch.topic in TOPICS else "control"
            qos = parse_offered_qos(ch.metadata.get("offered_qos_profiles", "")) \
                or dict(QOS_KINDS[kind])
            topics.append(TopicRecord(TopicInfo(ch.topic, typ, qos), int(counts.get(cid, 0)),
                                      ch.metadata.get("topic_type_hash", "")))
        start = int(stats.message_start_time) if stats else 0
        end = int(stats.message_end_time) if stats else 0
    total = sum(t.message_count for t in topics)
    write_metadata(folder, relative_file_paths=[mcap.name], topics=topics,
                   starting_time_ns=start, duration_ns=end - start, custom_data=custom)
    return FolderRecovery(mcap, meta_path, total, kept)
