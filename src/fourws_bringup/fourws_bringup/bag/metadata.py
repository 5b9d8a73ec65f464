"""metadata.yaml of a bag folder, and QoS as rosbag2 (Jazzy, version 9) writes it.

:func:`build_metadata` makes the ``rosbag2_bagfile_information`` mapping of a bag
(docs/bags.md, "Layout"): one :class:`TopicRecord` per topic (name, type, offered QoS,
message count, type hash); :func:`write_metadata` writes it atomically (temporary file, then
rename). A topic's offered QoS is a full rosbag2 profile (:func:`qos_profile_dict`; deadline,
lifespan and lease infinite, as rclpy's defaults), in metadata.yaml as a mapping and in an
MCAP channel's ``offered_qos_profiles`` as YAML text (:func:`qos_yaml`);
:func:`parse_offered_qos` reads that text back (names, or rosbag2 version 8 integers).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from fourws_common.topics import TopicInfo

ROSBAG2_VERSION = 9
ROS_DISTRO = "jazzy"
INFINITE_DURATION = {"sec": 9223372036, "nsec": 854775807}  # RMW_DURATION_INFINITE
#: libyaml's emitter when PyYAML has it (same text, ~5x faster: metadata.yaml is rewritten
#: after every chunk by the recorder), else the pure-Python one.
_YAML_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


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
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except OSError:
        tmp.unlink(missing_ok=True)    # a full disk leaves the last whole metadata.yaml
        raise
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
