"""rclpy QoS profiles of the fourws graph, built from the QoS kinds of ``fourws_common.topics``.

The values and the reason of each kind are in that table (docs/graph.md, "Topics (100 Hz,
simulated time)"); this module only turns them into ``QoSProfile`` objects (``CONTROL_QOS``,
``LATCHED_QOS``, ``CLOCK_QOS``, ``LATEST_QOS`` and ``NEWEST_QOS`` -- subscriber side -- and
``DIAGNOSTICS_QOS``), and converts between a profile and the plain ``history, depth,
reliability, durability`` values a bag records (:func:`profile_from_dict`,
:func:`dict_from_profile`), for the recorder and the replay.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from fourws_common.topics import QOS_KINDS, Topic


def profile_from_dict(q: Mapping[str, Any]) -> QoSProfile:
    """rclpy profile from ``history, depth, reliability, durability`` names (rosbag2's; see
    ``fourws_bringup.bag.metadata.parse_offered_qos``). A depth below 1 becomes 1."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if q["history"] == "keep_all" else HistoryPolicy.KEEP_LAST,
        depth=max(1, int(q["depth"])),
        reliability=(ReliabilityPolicy.BEST_EFFORT if q["reliability"] == "best_effort"
                     else ReliabilityPolicy.RELIABLE),
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if q["durability"] == "transient_local"
                    else DurabilityPolicy.VOLATILE))


def dict_from_profile(profile: QoSProfile) -> dict[str, Any]:
    """``history, depth, reliability, durability`` names of an rclpy profile (for the bag)."""
    return {"history": "keep_all" if profile.history == HistoryPolicy.KEEP_ALL else "keep_last",
            "depth": int(profile.depth),
            "reliability": ("best_effort" if profile.reliability == ReliabilityPolicy.BEST_EFFORT
                            else "reliable"),
            "durability": ("transient_local"
                           if profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
                           else "volatile")}


#: One rclpy profile per QoS kind of the table (``fourws_common.topics.QOS_KINDS``).
PROFILES: dict[str, QoSProfile] = {name: profile_from_dict(kind.as_dict())
                                   for name, kind in QOS_KINDS.items()}

CONTROL_QOS = PROFILES["control"]
LATCHED_QOS = PROFILES["latched"]
CLOCK_QOS = PROFILES["clock"]
LATEST_QOS = PROFILES["latest"]
NEWEST_QOS = PROFILES["newest"]
DIAGNOSTICS_QOS = PROFILES["diagnostics"]


def qos_of(topic: Topic) -> QoSProfile:
    """The profile a topic of the table is offered and subscribed with (its QoS kind)."""
    return PROFILES[topic.qos]
