"""The topics of the fourws graph and their QoS, as plain data: the one table of both.

Each graph topic has its name, ROS type (``pkg/msg/Type``), QoS kind and why it exists; each
QoS kind its history, depth, reliability, durability and why. Pure Python (no rclpy), so the
bag code and the pure cores can read it; ``fourws_common.qos`` turns a kind into an rclpy
``QoSProfile``. ``Topic.name`` is the topic's name in the root namespace, as the table, the
bags and the tools name it; nodes subscribe and publish ``Topic.ros_name``, which is relative
(``vehicle/state``), so a node started in a namespace (``-r __ns:=/car1``) moves its topics
with it and two cars can share a domain. ``/clock`` (one simulated clock per domain, as
``use_sim_time`` expects) and ``/diagnostics`` (the one topic diagnostic aggregators read)
stay absolute. The same table, with each topic's publishers and subscribers: docs/graph.md,
"Topics (100 Hz, simulated time)".

Also here: :class:`TopicInfo` (a topic as a bag records it: name, type, offered QoS values)
and :func:`topic_info`, which looks a recorder's topic spec up in the table.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class QosKind:
    """One QoS profile of the graph as plain values (rosbag2's names), and why."""

    history: str
    depth: int
    reliability: str
    durability: str
    reason: str

    def as_dict(self) -> dict[str, Any]:
        """``history, depth, reliability, durability`` (a bag's offered-QoS values)."""
        return {"history": self.history, "depth": self.depth, "reliability": self.reliability,
                "durability": self.durability}


QOS_KINDS: dict[str, QosKind] = {
    "control": QosKind(
        "keep_last", 1000, "reliable", "volatile",
        "Per-step control and state traffic: reliable so lockstep never loses a step; a deep "
        "queue (10 s of steps) so a subscriber starved of CPU for a while (the recorder, with "
        "six processes on two cores at several times real time) catches up instead of "
        "dropping: at depth 100 the recorder lost up to 10 % of the steps of a run under load. "
        "Loss is still detected from the bag (missing_steps in metrics.json) and logged by "
        "the recorder."),
    "latched": QosKind(
        "keep_last", 1, "reliable", "transient_local",
        "Reference trajectory and path (and the run status): published once; late joiners "
        "(the recorder, rviz) must get it."),
    "clock": QosKind(
        "keep_last", 1000, "reliable", "volatile",
        "/clock: reliable in lockstep so sim-time users see every tick; depth as the control "
        "traffic."),
    "latest": QosKind(
        "keep_last", 1, "reliable", "volatile",
        "Subscriber side only (no topic offers it): the controllers' view of the vehicle "
        "state with ``sync: lockstep``, where only the newest matters. Keep-last 1 means a "
        "node that fell behind takes the newest state, not a backlog of old ones; in "
        "lockstep one state is in flight at a time, so nothing is lost."),
    "newest": QosKind(
        "keep_last", 1, "best_effort", "volatile",
        "Subscriber side only: a controller's view of the vehicle state with ``sync: latest`` "
        "(realtime). Best effort, so a state lost while the node stalled is not repaired: a "
        "reliable reader delivers nothing past a lost sample until the writer's next heartbeat "
        "re-sends it (measured after a 2 s SIGSTOP of the MPC: its answer came 2.2 s after "
        "SIGCONT with Fast DDS's 3 s heartbeat); the newest state is what a late node needs."),
    "diagnostics": QosKind(
        "keep_last", 10, "reliable", "volatile",
        "/diagnostics: as diagnostic_updater publishes it (reliable, volatile), a queue of "
        "10."),
}


@dataclass(frozen=True)
class Topic:
    """One topic of the graph: name, ROS type, the QoS kind it is offered with, and why."""

    name: str
    type: str
    qos: str
    reason: str

    @property
    def ros_name(self) -> str:
        """The name a node uses: relative to its namespace, except :data:`GLOBAL_NAMES`."""
        return self.name if self.name in GLOBAL_NAMES else self.name.lstrip("/")


#: Topics that stay absolute under a namespace (see the module docstring).
GLOBAL_NAMES = ("/clock", "/diagnostics")


CLOCK = Topic("/clock", "rosgraph_msgs/msg/Clock", "clock",
              "simulated time from the plant, one tick per step, for use_sim_time users")
VEHICLE_STATE = Topic("/vehicle/state", "fourws_msgs/msg/VehicleState", "control",
                      "the plant's state of each step: starts the controllers' chain")
VEHICLE_GROUND_TRUTH = Topic("/vehicle/ground_truth", "fourws_msgs/msg/VehicleState", "control",
                             "the plant's true state of each step when /vehicle/state is "
                             "sensed (a realistic condition): every metric is computed on it")
VEHICLE_ODOM = Topic("/vehicle/odom", "nav_msgs/msg/Odometry", "control",
                     "the same state as standard odometry, for standard tools")
VEHICLE_IMU = Topic("/vehicle/imu", "sensor_msgs/msg/Imu", "control",
                    "yaw rate and body accelerations as a car's IMU gives them (the plant with "
                    "publish_standard_sensors; the adapter's input)")
VEHICLE_JOINT_STATES = Topic("/vehicle/joint_states", "sensor_msgs/msg/JointState", "control",
                             "road-wheel steer angles and wheel spin rates as joints (the plant "
                             "with publish_standard_sensors; the adapter's input)")
REFERENCE_TRAJECTORY = Topic("/reference/trajectory", "fourws_msgs/msg/ReferenceTrajectory",
                             "latched", "the scenario's reference for the MPC and speed PID, "
                             "once per run")
REFERENCE_PATH = Topic("/reference/path", "nav_msgs/msg/Path", "latched",
                       "the reference path as nav_msgs/Path, for standard tools")
MPC_COMMAND = Topic("/control/mpc_command", "fourws_msgs/msg/MpcCommand", "control",
                    "the MPC's steer angles (to the plant) and yaw moment (to the allocator)")
MPC_DIAGNOSTICS = Topic("/control/mpc_diagnostics", "fourws_msgs/msg/MpcDiagnostics",
                        "control", "the MPC's per-step solver figures, for the recorder")
DRIVE_COMMAND = Topic("/control/drive_command", "fourws_msgs/msg/DriveCommand", "control",
                      "the speed PID's total drive torque, to the allocator")
WHEEL_TORQUES = Topic("/control/wheel_torques", "fourws_msgs/msg/WheelTorques", "control",
                      "the allocator's four wheel torques and unmet demand, to the plant (and "
                      "the unmet yaw moment back to the MPC)")
RUN_STATUS = Topic("/run/status", "std_msgs/msg/String", "latched",
                   "the plant's run state as JSON (start, heartbeats, end), for the runner "
                   "and the bag")
DIAGNOSTICS = Topic("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", "diagnostics",
                    "each node's rejected-input and error counts")

#: The graph's topics by name, in the order a bag records them by default.
TOPICS: dict[str, Topic] = {t.name: t for t in (
    CLOCK, VEHICLE_STATE, VEHICLE_GROUND_TRUTH, VEHICLE_ODOM, VEHICLE_IMU,
    VEHICLE_JOINT_STATES, REFERENCE_TRAJECTORY,
    REFERENCE_PATH, MPC_COMMAND,
    MPC_DIAGNOSTICS, DRIVE_COMMAND, WHEEL_TORQUES, RUN_STATUS, DIAGNOSTICS)}
DEFAULT_TOPICS: tuple[str, ...] = tuple(TOPICS)


@dataclass(frozen=True)
class TopicInfo:
    """One recorded topic: name, ROS type (``pkg/msg/Type``) and the QoS it is offered with."""

    name: str
    type: str
    qos: Mapping[str, Any] = field(default_factory=lambda: QOS_KINDS["control"].as_dict())


def topic_info(spec: str) -> TopicInfo:
    """A topic of the graph by name, or ``/name:pkg/msg/Type`` for any other topic.

    Raises ``ValueError`` naming the topic when its type is not known.
    """
    name, _, typ = spec.partition(":")
    name = name.strip()
    if typ:
        return TopicInfo(name, normalise_type(typ.strip()), offered_qos(name))
    if name not in TOPICS:
        raise ValueError(f"topics: unknown topic '{name}' (known: {', '.join(TOPICS)}; "
                         "give others as '/name:pkg/msg/Type')")
    return TopicInfo(name, TOPICS[name].type, offered_qos(name))


def graph_name(resolved: str, namespace: str) -> str:
    """The table name of a topic a node in ``namespace`` resolved to ``resolved``
    (``/car1/vehicle/state`` in ``/car1`` -> ``/vehicle/state``); other names unchanged."""
    ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
    if ns and resolved.startswith(ns + "/") and resolved[len(ns):] in TOPICS:
        return resolved[len(ns):]
    return resolved


def namespace_of(topic_names: Iterable[str]) -> str:
    """The namespace a set of recorded topics was published in: the prefix of the one that
    ends in ``/vehicle/state`` (``/car1`` for ``/car1/vehicle/state``); ``/`` for the root
    namespace or when none does."""
    for name in topic_names:
        if name.endswith(VEHICLE_STATE.name):
            return name[: -len(VEHICLE_STATE.name)] or "/"
    return "/"


def qos_kind(name: str) -> str:
    """The QoS kind of a graph topic; ``control`` for a topic not in the table."""
    return TOPICS[name].qos if name in TOPICS else "control"


def offered_qos(name: str) -> dict[str, Any]:
    """The offered-QoS values of a topic (those of :func:`qos_kind`)."""
    return QOS_KINDS[qos_kind(name)].as_dict()


def normalise_type(type_name: str) -> str:
    """``pkg/Type`` or ``pkg/msg/Type`` -> ``pkg/msg/Type``."""
    parts = type_name.strip().split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    if len(parts) == 3 and parts[1] == "msg":
        return type_name.strip()
    raise ValueError(f"not a message type name: '{type_name}' (expected pkg/msg/Type)")
