"""Recorder node: every topic of the graph, serialized as received, into a rosbag2-layout MCAP bag.

Subscribes to each topic in ``topics`` (docs/bags.md, "Recording"), resolved in the recorder's
namespace (``-r __ns:=/car1`` records ``/car1/vehicle/state``), with ``raw=True`` and the QoS
its publisher offers (the topic table's QoS kind, ``fourws_common.topics``), and appends every
message to ``output_dir`` through :class:`fourws_bringup.bag.writer.BagWriter`. Times as
rosbag2 writes them (docs/bags.md, "Layout"): ``log_time`` the receive time on the node's clock
(simulated under ``use_sim_time``), ``publish_time`` and ``sequence`` from DDS's message info,
taken on a thread of their own (:mod:`fourws_bringup.info_taker`); ``custom_data`` in
``metadata.yaml`` says which.

Durability: chunks of ``chunk_size_bytes`` of uncompressed messages or ``chunk_max_span_s`` of
log time, whichever comes first (zstd), each flushed, and ``metadata.yaml`` rewritten with the
counts on disk, so a killed recorder loses at most the open chunk (``fourws bag recover`` makes
its MCAP whole again).

Start gate (``start_gate_topic``): that topic is subscribed to last, once every other recorded
per-step topic has a matched publisher and ``start_gate_settle_s`` more has passed (the
recorder sees a match before the publisher has matched it back), or after
``start_gate_timeout_s`` with a warning naming the unmatched topics.

Loss count (``LOST`` in the closing log line): per per-step topic, the step stamps missing
between consecutive received stamps (:class:`StampGaps`; the step period is the smallest stamp
difference seen on any of them), or DDS's message-lost count when that is larger.

Stopping: on SIGINT or SIGTERM the node keeps taking messages until none has arrived for
``drain_quiet_s`` *and* no writer is left matched on a per-step topic (at most
``drain_max_s``), or at once when no writer is left matched on any recorded topic; then
``destroy_node`` takes what is still queued (:meth:`InfoTaker.stop`), finalises the file (last
chunk, summary, footer) and writes the final ``metadata.yaml``, exactly once (also when rclpy
shuts down first).
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.clock import Clock as RclClock
from rclpy.clock import ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSProfile

from fourws_common.exit_codes import ExitCode
from fourws_common.input_guard import MAX_STAMP_JUMP_NS, Stamp, StampGate
from fourws_common.node_main import run_node
from fourws_common.params import param
from fourws_common.qos import PROFILES, dict_from_profile, profile_from_dict
from fourws_common.ros_params import ParamBinding
from fourws_common.topics import (
    DEFAULT_TOPICS,
    DIAGNOSTICS,
    TOPICS,
    TopicInfo,
    graph_name,
    qos_kind,
    topic_info,
)

from .bag.errors import BagError
from .bag.schema import cdr_stamp_ns
from .bag.writer import BagWriter
from .info_taker import InfoTaker

#: QoS kinds of the graph's topics that carry one message per step, stamped with the step.
PER_STEP_KINDS = ("control", "clock")


class StampGaps:
    """The stamp differences between consecutive received messages of one per-step topic,
    counted by size (a few distinct sizes in a run), so the missing steps can be counted once
    the step period is known (:meth:`missing`). A stamp not after the last one (the lockstep
    plant's repeat of a waiting state) is no gap."""

    __slots__ = ("gaps", "gate")

    def __init__(self) -> None:
        self.gate = StampGate(MAX_STAMP_JUMP_NS)
        self.gaps: dict[int, int] = {}

    @property
    def last_ns(self) -> int | None:
        return self.gate.last_ns

    def add(self, stamp_ns: int) -> None:
        """The nodes' stamp rule (:class:`~fourws_common.input_guard.StampGate`): a stray
        far ahead or behind is no gap; a confirmed jump back (a new run into the same
        recorder) starts counting afresh, and a confirmed jump ahead is no loss either."""
        last, pending = self.gate.last_ns, self.gate.pending_ns
        verdict = self.gate.check(stamp_ns)
        if verdict is Stamp.NEW and last is not None:
            steps = [stamp_ns - last]
        elif verdict is Stamp.JUMPED and last is not None and pending is not None \
                and pending > last:
            # the plant stamps every step: a long run of lost messages, not a time jump
            steps = [pending - last, stamp_ns - pending]
        else:
            return
        for d in steps:
            if d > 0:
                self.gaps[d] = self.gaps.get(d, 0) + 1

    def min_gap_ns(self) -> int | None:
        """The smallest stamp difference seen (the step period once two steps followed)."""
        return min(self.gaps) if self.gaps else None

    def missing(self, period_ns: int) -> int:
        """Step stamps absent between the first and the last received stamp."""
        if period_ns <= 0:
            return 0
        return sum(max(0, (d + period_ns // 2) // period_ns - 1) * n
                   for d, n in self.gaps.items())


def lost_counts(gaps: Mapping[str, StampGaps], dds_lost: Mapping[str, int],
                period_ns: int | None = None) -> dict[str, int]:
    """Messages lost per topic (only topics that lost some): the larger of the step stamps
    missing between received ones (``gaps``; ``period_ns`` defaults to the smallest stamp
    difference of any topic, the step period) and DDS's message-lost total (``dds_lost``).
    Not their sum: a message DDS reports lost is also a missing stamp."""
    if period_ns is None:
        seen = [g for g in (x.min_gap_ns() for x in gaps.values()) if g is not None]
        period_ns = min(seen) if seen else 0
    out: dict[str, int] = {}
    for topic in sorted(set(gaps) | set(dds_lost)):
        g = gaps.get(topic)
        n = max(g.missing(period_ns) if g is not None else 0, int(dds_lost.get(topic, 0)))
        if n:
            out[topic] = n
    return out



def own_diagnostics(namespace: str):
    """A filter of serialized /diagnostics arrays for a recorder in ``namespace``: it keeps
    the statuses of nodes in that namespace (``/car1/mpc_node``, ``/car1/mpc_node: runtime``)
    and returns the array re-serialized, the bytes unchanged when all are kept, or None when
    none is. /diagnostics is one topic for every graph of a domain (ROS convention); a car's
    bag holds its own nodes' diagnostics only."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import deserialize_message, serialize_message

    ns = namespace.rstrip("/")

    def node_namespace(status_name: str) -> str:
        return status_name.split(":", 1)[0].rsplit("/", 1)[0]

    def keep(data: bytes) -> bytes | None:
        msg = deserialize_message(data, DiagnosticArray)
        mine = [s for s in msg.status if node_namespace(s.name) == ns]
        if len(mine) == len(msg.status):
            return data
        if not mine:
            return None
        msg.status = mine
        return serialize_message(msg)
    return keep

@dataclass(frozen=True)
class RecorderConfig:
    output_dir: str = param("", "bag folder to create (must not exist or be empty)")
    chunk_size_bytes: int = param(262144, "uncompressed size of one MCAP chunk; a killed "
                                  "recorder loses at most one chunk", lo=4096, hi=64 * 2**20,
                                  unit="bytes")
    chunk_max_span_s: float = param(1.0, "a chunk is also completed once its messages span "
                                    "this much log time: a killed recorder loses at most "
                                    "this much", lo=0.05, hi=3600.0, unit="s")
    compression: str = param("zstd", "chunk compression", choices=("zstd", "lz4", "none"))
    drain_quiet_s: float = param(0.3, "after a stop request, end once no message has come "
                                 "for this long (at once when no writer is left on any "
                                 "recorded topic)", lo=0.0, hi=10.0, unit="s")
    drain_max_s: float = param(3.0, "after a stop request, end after this long at most (more "
                               "than a writer's wait for its acknowledgements, 2 s)",
                               lo=0.0, hi=60.0, unit="s")
    start_gate_topic: str = param("", "subscribe to this recorded topic only once every other "
                                  "per-step topic has a matched publisher (empty: all at once)")
    start_gate_settle_s: float = param(0.5, "after the last per-step publisher matched, wait "
                                       "this long before subscribing to start_gate_topic",
                                       lo=0.0, hi=10.0, unit="s")
    start_gate_timeout_s: float = param(10.0, "subscribe to start_gate_topic after this long "
                                        "even if some publisher is missing", lo=0.0, hi=300.0,
                                        unit="s")

    def __post_init__(self) -> None:
        if not self.output_dir:
            raise ValueError("output_dir: must be set to the bag folder to create")
        if self.start_gate_topic and not self.start_gate_topic.startswith("/"):
            raise ValueError(f"start_gate_topic: expected an absolute topic name, got "
                             f"{self.start_gate_topic!r}")
        if self.drain_quiet_s > self.drain_max_s:
            raise ValueError(f"drain_quiet_s ({self.drain_quiet_s}) must not exceed "
                             f"drain_max_s ({self.drain_max_s})")


def graph_kind(info: TopicInfo) -> str | None:
    """The QoS kind of a graph topic recorded with its graph type, else None."""
    topic = TOPICS.get(info.name)
    return topic.qos if topic is not None and topic.type == info.type else None


def qos_of(info: TopicInfo) -> QoSProfile:
    """The rclpy profile to subscribe a topic with: the graph's own profile when known."""
    kind = graph_kind(info)
    return PROFILES[kind] if kind is not None else profile_from_dict(info.qos)


def message_class(type_name: str):
    """The generated Python class of ``pkg/msg/Type``."""
    import importlib

    pkg, _, name = type_name.split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.msg"), name)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"topics: message type {type_name} is not installed") from exc


#: the recorder's parameters read at start only (a runtime set is refused, naming them)
START_ONLY = ("topics", "output_dir", "chunk_size_bytes", "chunk_max_span_s", "compression",
              "start_gate_topic", "start_gate_settle_s", "start_gate_timeout_s")


class RecorderNode(Node):
    """Subscribes serialized, writes the bag; all storage logic is in fourws_bringup.bag."""

    def __init__(self) -> None:
        super().__init__("recorder_node")
        self.done = False
        self._lock = threading.Lock()
        self._finalised = False
        self.writer: BagWriter | None = None
        self._stop_requested_at: float | None = None
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._on_signal)
        self.params = ParamBinding(self, RecorderConfig)
        self.declare_parameter("topics", list(DEFAULT_TOPICS), ParameterDescriptor(
            description="topics to record: graph topic names, or '/name:pkg/msg/Type'"))
        self.add_on_set_parameters_callback(self._reject_runtime_change)
        cfg = self.params.config
        specs = self.get_parameter("topics").value
        if not isinstance(specs, list | tuple) or not specs or not all(
                isinstance(s, str) and s for s in specs):
            raise ValueError(f"topics: expected a non-empty list of topic names, got {specs!r}")
        infos = [topic_info(s) for s in specs]
        names = [i.name for i in infos]
        if len(set(names)) != len(names):
            raise ValueError(f"topics: a topic is listed twice: {names}")
        # A graph topic is subscribed by its relative name, so a recorder in a namespace
        # records that namespace's graph; the bag holds the resolved names, as rosbag2's.
        profiles, kinds = {}, {}
        for i, info in enumerate(infos):
            resolved = self._resolve(info.name)
            profiles[resolved], kinds[resolved] = qos_of(info), graph_kind(info)
            infos[i] = TopicInfo(resolved, info.type, dict_from_profile(profiles[resolved]))
        names = [i.name for i in infos]
        classes = {info.name: message_class(info.type) for info in infos}
        sim = bool(self.get_parameter("use_sim_time").value)
        custom = {"fourws_log_time": "sim_time" if sim else "ros_time",
                  "fourws_publish_time": "send_time",
                  "fourws_namespace": self.get_namespace()}
        try:
            self.writer = BagWriter(cfg.output_dir, infos, chunk_size_bytes=cfg.chunk_size_bytes,
                                    chunk_max_span_ns=int(cfg.chunk_max_span_s * 1e9),
                                    compression=cfg.compression, library="fourws recorder_node",
                                    custom_data=custom)
        except (BagError, OSError) as exc:
            raise ValueError(f"output_dir: cannot create the bag: {exc}") from exc
        self.context.on_shutdown(self.finalise)
        self.taker = InfoTaker(self)
        self.received = 0
        self._last_rx = time.monotonic()
        self.lost: dict[str, int] = {}  # DDS's message-lost totals
        self.gaps = {i.name: StampGaps() for i in infos
                     if kinds[i.name] in PER_STEP_KINDS and self.writer.stamped(i.name)}
        self.matched: dict[str, int] = {}
        gate = self._resolve(cfg.start_gate_topic) if cfg.start_gate_topic else ""
        if gate and gate not in names:
            raise ValueError(f"start_gate_topic: {cfg.start_gate_topic} is not among the "
                             "recorded topics")
        per_step = [i.name for i in infos
                    if qos_kind(graph_name(i.name, self.get_namespace())) == "control"]
        self._gate_waits = [t for t in per_step if t != gate]
        self._drain_waits = per_step  # a stop drains until their writers have left
        self._pending_gate = next((i for i in infos if i.name == gate), None)
        self._profiles, self._classes = profiles, classes
        self._started_at = time.monotonic()
        self._all_matched_at: float | None = None
        for info in infos:
            if info is not self._pending_gate:
                self._subscribe(info.name)
        self.taker.start()
        self.create_timer(0.05, self._check_stop,
            clock=RclClock(clock_type=ClockType.STEADY_TIME))  # also under use_sim_time
        self.get_logger().info(
            f"recording {len(infos)} topics to {self.writer.path} (chunks of "
            f"{cfg.chunk_size_bytes} bytes, {cfg.compression}): {', '.join(names)}")

    def _resolve(self, name: str) -> str:
        """A graph topic's name in this node's namespace; any other name as given."""
        topic = TOPICS.get(name)
        return self.resolve_topic_name(topic.ros_name) if topic is not None else name

    def _subscribe(self, topic: str) -> None:
        def on_matched(info) -> None:
            self.matched[topic] = int(info.current_count)

        self.taker.subscribe(
            self._classes[topic], topic, self._profiles[topic], self._callback(topic),
            event_callbacks=SubscriptionEventCallbacks(
                message_lost=self._lost_callback(topic), matched=on_matched))

    def _check_gate(self) -> None:
        """Subscribe to the gate topic once every per-step topic has a publisher matched."""
        if self._pending_gate is None:
            return
        cfg = self.params.config
        now = time.monotonic()
        missing = [t for t in self._gate_waits if self.matched.get(t, 0) < 1]
        waited = now - self._started_at
        if missing and waited < cfg.start_gate_timeout_s:
            return
        if not missing:
            if self._all_matched_at is None:
                self._all_matched_at = now
            if now - self._all_matched_at < cfg.start_gate_settle_s:
                return
        topic = self._pending_gate.name
        self._pending_gate = None
        if missing:
            self.get_logger().warning(
                f"no publisher matched on {', '.join(missing)} after {waited:.1f} s: "
                f"subscribing to {topic} anyway; their first messages may be missing")
        else:
            self.get_logger().info(f"every per-step publisher matched after {waited:.2f} s: "
                                   f"subscribing to {topic}")
        self._subscribe(topic)

    def _reject_runtime_change(self, params):
        from rcl_interfaces.msg import SetParametersResult

        names = [p.name for p in params]
        if any(n in START_ONLY for n in names):
            return SetParametersResult(successful=False, reason="recorder parameters "
                                       f"{names} apply at start only")
        return SetParametersResult(successful=True)

    def _callback(self, topic: str):
        gaps = self.gaps.get(topic)
        own = (own_diagnostics(self.get_namespace())
               if graph_name(topic, self.get_namespace()) == DIAGNOSTICS.name else None)

        clock = self.get_clock()

        def on_message(data: bytes, info: dict) -> None:
            if own is not None:
                data = own(data)
                if data is None:       # another graph's nodes (a car in another namespace)
                    return
            now = clock.now().nanoseconds  # rosbag2's receive time: the node's clock
            sent = info.get("source_timestamp") or time.time_ns()
            seq = info.get("publication_sequence_number")
            self._last_rx = time.monotonic()
            with self._lock:
                if self._finalised or self.writer is None:
                    return
                if gaps is not None:
                    stamp = cdr_stamp_ns(data)
                    if stamp is not None and stamp >= 0:
                        gaps.add(stamp)
                try:
                    self.writer.write(topic, data, now, sent, seq)
                except OSError as exc:
                    self._write_failed(exc)
                    return
                self.received += 1
        return on_message

    def _write_failed(self, exc: OSError) -> None:
        """A write error (a full disk): keep what is on disk, say so once, and end with exit
        code 1 (the run then ends as an error naming this node). Called under the lock."""
        self._finalised = True
        self.writer.abandon()
        self.exit_code = ExitCode.ERROR
        self.done = True
        self.get_logger().error(
            f"cannot write the bag {self.writer.path}: {exc.strerror or exc} (the file system "
            f"of {self.writer.folder} is full or failing); recording stopped after "
            f"{self.received} messages, {self.writer.chunks_written} chunks on disk: `fourws "
            f"bag recover {self.writer.folder}` restores them once there is space")

    def lost_counts(self) -> dict[str, int]:
        """Messages lost per topic so far (:func:`lost_counts`)."""
        return lost_counts(self.gaps, self.lost)

    def _lost_callback(self, topic: str):
        def on_lost(info) -> None:
            self.lost[topic] = int(info.total_count)
            self.get_logger().warning(
                f"{topic}: {info.total_count_change} message(s) lost before the recorder took "
                f"them ({info.total_count} so far); the queue depth was too small for the lag",
                throttle_duration_sec=1.0)
        return on_lost

    def _on_signal(self, signum, _frame) -> None:
        if self._stop_requested_at is None:
            self._stop_requested_at = time.monotonic()
        else:
            self.done = True  # a second signal: stop draining

    def _check_stop(self) -> None:
        if self.taker.error is not None and not self.done:
            self.get_logger().error(f"the message taker failed ({self.taker.error!r}): "
                                    "closing the bag with what it holds")
            self.done = True
            return
        self._check_gate()
        if self._stop_requested_at is None or self.done:
            return
        cfg = self.params.config
        now = time.monotonic()
        quiet = now - max(self._last_rx, self._stop_requested_at) >= cfg.drain_quiet_s
        writers = [t for t in self._drain_waits if self.matched.get(t, 0) > 0]
        # no writer left on any topic: every sample they sent is acknowledged, so queued
        # here (destroy_node takes the last ones); waiting for quiet would add nothing
        alone = not any(self.matched.values())
        if alone or (quiet and not writers):
            self.done = True
        elif now - self._stop_requested_at >= cfg.drain_max_s:
            self.done = True
            if writers:
                self.get_logger().warning(
                    f"stopped draining after {cfg.drain_max_s:.1f} s with writers still on "
                    f"{', '.join(writers)}: their last messages may be missing")

    def finalise(self) -> None:
        """Finish the MCAP file and write metadata.yaml; runs once, whoever calls first."""
        with self._lock:
            if self._finalised or self.writer is None:
                return
            self._finalised = True
            try:
                self.writer.close()
            except OSError as exc:
                self._write_failed(exc)
                return
            counts = {k: r.message_count for k, r in self.writer.records.items()}
            lost_by_topic = self.lost_counts()
        lost = f"; LOST {lost_by_topic}" if lost_by_topic else ""
        self.get_logger().info(f"bag {self.writer.folder} closed: {sum(counts.values())} "
                               f"messages ({', '.join(f'{k} {v}' for k, v in counts.items())})"
                               f"{lost}")

    def destroy_node(self) -> None:
        self.taker.stop()
        self.finalise()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run_node(RecorderNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
