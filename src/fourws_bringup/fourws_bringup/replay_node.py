"""Replay node: publish a recorded bag's serialized messages again, in recorded order, with /clock.

Each replayed topic gets a publisher of its recorded type and offered QoS (latched topics stay
transient_local), and its recorded CDR bytes are published as they are (``publish(bytes)``;
docs/bags.md, "Replay"). ``/clock`` is published from the header stamps of the per-step topics
(the run's simulated time; /diagnostics and the like carry the nodes' own clock): before each
such message whose stamp is later than every stamp so far, i.e. once per simulated step. A
stamp more than the nodes' jump limit away from the newest (a stray) neither paces nor clocks.

Timing: with ``pacing: stamp`` a message is due at ``t0 + (s - s0) / rate``, ``s`` the
largest header stamp so far (simulated time, so ``rate: 1`` is real time); with
``pacing: recorded`` the recorded receive times are used instead. ``rate: 0`` publishes as
fast as possible: a subscriber slower than that loses the oldest messages beyond its KEEP_LAST
depth (1000 on the per-step topics); use ``lockstep_topic`` to replay at the pace of a
controller instead.

Lockstep (``lockstep_topic``, e.g. ``/control/mpc_command``): after publishing a
``lockstep_trigger`` message (``/vehicle/state``) stamped k, nothing more is published until a
message stamped k arrives on ``lockstep_topic`` (or ``lockstep_timeout_s`` passes, which is
logged and counted).

Start: optionally wait until every replayed topic has a subscriber (and, in lockstep, the
lockstep topic a publisher), at most ``wait_timeout_s``, then ``start_delay_s``. End: after
the last message, wait for reliable subscribers to acknowledge (``ack_timeout_s``), log the
count and set ``done``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.clock import Clock as RclClock
from rclpy.clock import ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from fourws_common.conversions import ns_to_stamp
from fourws_common.input_guard import MAX_STAMP_JUMP_NS
from fourws_common.node_main import run_node
from fourws_common.params import param
from fourws_common.qos import PROFILES, profile_from_dict, qos_of
from fourws_common.ros_params import ParamBinding
from fourws_common.topics import (
    CLOCK,
    RUN_STATUS,
    TOPICS,
    VEHICLE_STATE,
    graph_name,
    namespace_of,
    qos_kind,
)

from .bag.errors import BagError
from .bag.reader import McapBag
from .bag.schema import cdr_stamp_ns, first_field_is_stamp
from .recorder_node import message_class

BATCH = 500  # most messages published in one timer tick


@dataclass(frozen=True)
class ReplayConfig:
    bag: str = param("", "bag folder, run folder or .mcap file to replay")
    rate: float = param(1.0, "speed factor: 1 as recorded (real time), 0 as fast as possible",
                        lo=0.0, hi=1000.0)
    pacing: str = param("stamp", "time base of the pacing: header stamps (simulated time) or "
                        "recorded receive times", choices=("stamp", "recorded"))
    publish_clock: bool = param(True, "publish /clock from the header stamps")
    lockstep_topic: str = param("", "after each trigger message stamped k, wait for a message "
                                "stamped k on this topic ('' = off)")
    lockstep_trigger: str = param(VEHICLE_STATE.name, "topic whose messages wait for the "
                                  "lockstep answer")
    lockstep_timeout_s: float = param(10.0, "lockstep: go on after this wall time without an "
                                      "answer (logged)", lo=0.01, hi=3600.0, unit="s")
    wait_for_subscribers: bool = param(False, "before starting, wait until every replayed "
                                       "topic has a subscriber")
    wait_timeout_s: float = param(10.0, "start anyway after this wall time", lo=0.0,
                                  hi=3600.0, unit="s")
    start_delay_s: float = param(0.0, "wall time to wait before the first message", lo=0.0,
                                 hi=3600.0, unit="s")
    ack_timeout_s: float = param(1.0, "at the end, wait at most this long for reliable "
                                 "subscribers to acknowledge", lo=0.0, hi=60.0, unit="s")

    def __post_init__(self) -> None:
        if not self.bag:
            raise ValueError("bag: must be set to a bag folder, run folder or .mcap file")


def _ros_name(name: str) -> str:
    """A graph topic's node-side (relative) name; any other name as given."""
    return TOPICS[name].ros_name if name in TOPICS else name


class ReplayNode(Node):
    """Reads the bag lazily (fourws_bringup.bag.reader.McapBag) and publishes on a 1 ms
    timer."""

    def __init__(self) -> None:
        super().__init__("replay_node")
        self.done = False
        self.exit_code = 0
        self.params = ParamBinding(self, ReplayConfig, on_change=self._fixed)
        cfg = self.cfg = self.params.config
        topics_param = self.declare_parameter("topics", Parameter.Type.STRING_ARRAY,
                                              ParameterDescriptor(description=(
                                                  "topics to replay (unset: every recorded "
                                                  "topic but /clock and /run/status)"))).value
        self.add_on_set_parameters_callback(self._keep_topics)
        try:
            self.bag = McapBag(cfg.bag)
        except BagError as exc:
            raise ValueError(f"bag: {exc}") from exc
        recorded = self.bag.channels
        if topics_param:
            missing = [t for t in topics_param if t not in recorded]
            if missing:
                self.bag.close()
                raise ValueError(f"topics: {missing} not in the bag (it has "
                                 f"{', '.join(sorted(recorded))})")
            self.topics = list(dict.fromkeys(topics_param))
        else:
            self.topics = [t for t in recorded
                           if graph_name(t, namespace_of(recorded)) not in (CLOCK.name,
                                                                           RUN_STATUS.name)]
        self.pubs = {}
        self.stamped: dict[str, bool] = {}
        # a graph topic is published by its relative name, in this node's namespace, whatever
        # namespace it was recorded in (a bag of /car1 replays into /car2 with __ns:=/car2)
        ns = namespace_of(recorded)
        self._graph = {t: graph_name(t, ns) for t in recorded}
        for t in self.topics:
            ch = recorded[t]
            g = self._graph[t]
            # the offered QoS as recorded; the table's for a channel without one
            qos = profile_from_dict(ch.qos) if ch.qos else PROFILES[qos_kind(g)]
            self.pubs[t] = self.create_publisher(message_class(ch.type), _ros_name(g), qos)
            # only the per-step topics' stamps are the run's simulated time: /diagnostics
            # and the like are stamped on the nodes' own (wall) clock
            self.stamped[t] = (first_field_is_stamp(ch.definition)
                               and qos_kind(self._graph[t]) == "control")
        self.clock_pub = None
        if cfg.publish_clock and CLOCK.name not in self.topics:
            self.clock_pub = self.create_publisher(Clock, CLOCK.ros_name, qos_of(CLOCK))
        self.lockstep = bool(cfg.lockstep_topic)
        self._trigger: str | None = None
        self.answered: set[int] = set()
        self.lockstep_misses = 0
        if self.lockstep:
            lock = graph_name(cfg.lockstep_topic, ns)
            known = (recorded.get(cfg.lockstep_topic) or TOPICS.get(lock)
                     or next((recorded[t] for t, g in self._graph.items() if g == lock), None))
            ltype = known.type if known is not None else None
            if ltype is None:
                raise ValueError(f"lockstep_topic: type of {cfg.lockstep_topic} unknown (not in "
                                 "the bag nor a graph topic)")
            trigger = graph_name(cfg.lockstep_trigger, ns)
            self._trigger = next((t for t in self.topics
                                  if t == cfg.lockstep_trigger or self._graph[t] == trigger),
                                 None)
            if self._trigger is None:
                raise ValueError(f"lockstep_trigger: {cfg.lockstep_trigger} is not replayed")
            self._lock_sub = self.create_subscription(
                message_class(ltype), _ros_name(lock), self._on_answer,
                PROFILES[qos_kind(lock)], raw=True)
        self._messages = self.bag.messages(self.topics)
        self._next = None
        self.counts = {t: 0 for t in self.topics}
        self.clock_count = 0
        self._phase = "wait" if cfg.wait_for_subscribers else "delay"
        self._phase_start = time.monotonic()
        self._t0 = 0.0
        self._s0: int | None = None
        self._log0: int | None = None
        self._max_stamp: int | None = None
        self._waiting: tuple[int, float] | None = None
        self._timer = self.create_timer(0.001, self._tick,
            clock=RclClock(clock_type=ClockType.STEADY_TIME))  # also under use_sim_time
        self.get_logger().info(
            f"replaying {self.bag.path} ({', '.join(self.topics)}) at rate {cfg.rate} "
            f"({cfg.pacing}){'; lockstep on ' + cfg.lockstep_topic if self.lockstep else ''}")

    @staticmethod
    def _keep_topics(params: list[Parameter]) -> SetParametersResult:
        """``topics`` too is read at start."""
        if any(p.name == "topics" for p in params):
            return SetParametersResult(successful=False, reason="replay parameters are read "
                                       "at start: start another replay")
        return SetParametersResult(successful=True)

    @staticmethod
    def _fixed(_cfg: ReplayConfig) -> None:
        """A runtime set is refused: a replay reads its parameters at start (a changed rate
        or pacing was accepted and never applied)."""
        raise ValueError("replay parameters are read at start: start another replay")

    # -- lockstep ----------------------------------------------------------------------------
    def _on_answer(self, data: bytes) -> None:
        stamp = cdr_stamp_ns(data)
        if stamp is not None:
            self.answered.add(stamp)

    # -- main loop ---------------------------------------------------------------------------
    def _tick(self) -> None:
        if self.done:
            return
        now = time.monotonic()
        if self._phase == "wait":
            if self._ready() or now - self._phase_start >= self.cfg.wait_timeout_s:
                if not self._ready():
                    self.get_logger().warning(
                        f"starting without subscribers on {self._unmatched()} after "
                        f"{self.cfg.wait_timeout_s:.1f} s")
                self._phase, self._phase_start = "delay", now
            return
        if self._phase == "delay":
            if now - self._phase_start < self.cfg.start_delay_s:
                return
            self._phase, self._t0 = "run", now
        if self._waiting is not None:
            stamp, deadline = self._waiting
            if stamp not in self.answered:
                if now < deadline:
                    return
                self.lockstep_misses += 1
                self.get_logger().warning(
                    f"no {self.cfg.lockstep_topic} stamped {stamp} ns within "
                    f"{self.cfg.lockstep_timeout_s:.1f} s; going on")
            self._waiting = None
            self.answered = {a for a in self.answered if a >= stamp}  # a repeat of it may follow
        for _ in range(BATCH):
            if self._next is None:
                self._next = next(self._messages, None)
                if self._next is None:
                    self._finish()
                    return
            topic, log_ns, _pub_ns, data = self._next
            stamp = cdr_stamp_ns(data) if self.stamped[topic] else None
            if not self._due(stamp, log_ns, now):
                return
            self._next = None
            self._publish(topic, data, stamp)
            if (self.lockstep and topic == self._trigger and stamp is not None
                    and stamp not in self.answered):
                self._waiting = (stamp, time.monotonic() + self.cfg.lockstep_timeout_s)
                return

    def _on_timeline(self, stamp: int | None) -> bool:
        """A stamp of the run's simulated time: the first, or within the nodes' jump limit of
        the newest so far (a stray stamped far ahead or behind neither paces nor clocks)."""
        return stamp is not None and (self._max_stamp is None
                                      or abs(stamp - self._max_stamp) <= MAX_STAMP_JUMP_NS)

    def _due(self, stamp: int | None, log_ns: int, now: float) -> bool:
        rate = self.cfg.rate
        if self.cfg.pacing == "recorded":
            if self._log0 is None:
                self._log0 = log_ns
            offset_ns = log_ns - self._log0
        else:
            if not self._on_timeline(stamp) or self._s0 is None:
                return True
            offset_ns = max(stamp, self._max_stamp or stamp) - self._s0
        return rate == 0.0 or now >= self._t0 + offset_ns * 1e-9 / rate

    def _publish(self, topic: str, data: bytes, stamp: int | None) -> None:
        if self._on_timeline(stamp):
            if self._s0 is None:
                self._s0 = stamp
            if self._max_stamp is None or stamp > self._max_stamp:
                self._max_stamp = stamp
                if self.clock_pub is not None:
                    self.clock_pub.publish(Clock(clock=ns_to_stamp(stamp)))
                    self.clock_count += 1
        self.pubs[topic].publish(bytes(data))
        self.counts[topic] += 1

    def _unmatched(self) -> list[str]:
        out = [t for t, p in self.pubs.items() if p.get_subscription_count() < 1]
        if self.lockstep and self.count_publishers(self._lock_sub.topic_name) < 1:
            out.append(f"{self.cfg.lockstep_topic} (no publisher)")
        return out

    def _ready(self) -> bool:
        return not self._unmatched()

    def _finish(self) -> None:
        self._timer.cancel()
        deadline = time.monotonic() + self.cfg.ack_timeout_s
        pubs = [*self.pubs.values(), *([self.clock_pub] if self.clock_pub else [])]
        for p in pubs:
            p.wait_for_all_acked(Duration(seconds=max(0.0, deadline - time.monotonic())))
        total = sum(self.counts.values())
        wall = time.monotonic() - self._t0
        self.get_logger().info(
            f"replayed {total} messages in {wall:.2f} s "
            f"({', '.join(f'{t} {n}' for t, n in self.counts.items())}; /clock "
            f"{self.clock_count})"
            + (f"; {self.lockstep_misses} lockstep answers missed" if self.lockstep else ""))
        self.done = True

    def destroy_node(self) -> None:
        self.bag.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run_node(ReplayNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
