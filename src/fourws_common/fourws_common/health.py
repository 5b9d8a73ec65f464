"""What a node rejected, and why: counted, logged at a limited rate, published on /diagnostics.

Every fourws node owns one :class:`NodeHealth` (docs/graph.md, "Lifecycle and bad input").
``health.reject(kind, now_ns, text)`` counts a rejected input (or a fallback) under ``kind``
and logs ``text`` at most once per second of the caller's clock per kind;
``health.error(kind, now_ns, exc, what)`` does the same for an exception caught in a callback,
with the input that caused it. The counts go out as a ``diagnostic_msgs/DiagnosticArray`` on
``/diagnostics`` (one DiagnosticStatus named after the node: OK with no rejections, WARN once
any input was rejected, ERROR once a callback raised) every ``period_s`` of steady time and
within 0.1 s of a change, so a recorded run holds the final counts of every node
(``input_rejections`` in metrics.json).

A node that has a runtime condition to report (solver status, fallbacks, deadline misses, the
age of its newest input) registers a :class:`Runtime` provider; its status goes out in the
same array as a second DiagnosticStatus named ``<node>: runtime`` (OK, WARN or ERROR, as
``rqt_robot_monitor`` shows it), with text values, so it never mixes with the counts.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from fourws_common.conversions import RateLimitedLog
from fourws_common.qos import qos_of
from fourws_common.topics import DIAGNOSTICS

#: steady-clock period (s) of the change check; a change is published within this time.
CHANGE_POLL_S = 0.1
#: suffix of the runtime status's name
RUNTIME_SUFFIX = ": runtime"
OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR


@dataclass
class Runtime:
    """A node's runtime condition: level (OK, WARN, ERROR), one-line message, text values."""

    level: bytes = OK
    message: str = "OK"
    values: dict[str, str] = field(default_factory=dict)


def worst(*levels: bytes) -> bytes:
    """The most severe of diagnostic levels."""
    return max(levels, key=lambda b: b[0] if isinstance(b, bytes) else int(b))


#: steady seconds without an input after which a node's runtime status says it is stale
STALE_AFTER_S = 1.0


def with_input_age(rt: Runtime, age_s: float | None, what: str) -> Runtime:
    """``rt`` with ``input_age_s``, and WARN when no ``what`` came for :data:`STALE_AFTER_S`
    (a stopped plant or a lost link); ``age_s`` None: nothing received yet."""
    rt.values["input_age_s"] = "none yet" if age_s is None else f"{age_s:.3f}"
    if age_s is not None and age_s > STALE_AFTER_S:
        rt.level = worst(rt.level, WARN)
        stale = f"no {what} for {age_s:.1f} s"
        rt.message = stale if rt.message == "OK" else f"{rt.message}; {stale}"
    return rt


class NodeHealth:
    """Counters of rejected inputs and caught errors of one node (see the module docstring)."""

    def __init__(self, node: Node, period_s: float = 1.0) -> None:
        self._node = node
        self._logs: dict[str, RateLimitedLog] = {}
        self.errors = 0
        self._published: dict[str, int] | None = None
        self._since_publish_s = 0.0
        self._period_s = period_s
        self._pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS.ros_name,
                                          qos_of(DIAGNOSTICS))
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._timer = node.create_timer(CHANGE_POLL_S, self._tick, clock=steady)
        self._runtime: Callable[[], Runtime] | None = None

    def runtime(self, provider: Callable[[], Runtime]) -> None:
        """Publish ``provider()`` as this node's runtime status (module docstring)."""
        self._runtime = provider

    @property
    def counts(self) -> dict[str, int]:
        return {k: log.count for k, log in self._logs.items()}

    def _log(self, kind: str, level: str = "warning") -> RateLimitedLog:
        log = self._logs.get(kind)
        if log is None:
            logger = self._node.get_logger()
            log = RateLimitedLog(getattr(logger, level))
            self._logs[kind] = log
        return log

    def reject(self, kind: str, now_ns: int, text: str) -> None:
        """Count one rejected input of ``kind``; log ``text`` at a limited rate."""
        self._log(kind)(now_ns, text)

    def error(self, kind: str, now_ns: int, exc: BaseException, what: str) -> None:
        """Count an exception caught in a callback, logged with the input that caused it."""
        self.errors += 1
        self._log(kind, "error")(now_ns, f"{type(exc).__name__}: {exc} while handling {what}")

    def guard(self, topic: str, callback):
        """``callback`` wrapped so that no exception leaves it: it is counted and logged with
        the message that caused it (``callback_error``), and the node lives on."""
        def guarded(msg) -> None:
            try:
                callback(msg)
            except Exception as exc:  # noqa: BLE001 - a callback never kills the node
                stamp = getattr(getattr(msg, "header", None), "stamp", None)
                now_ns = (int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
                          if stamp is not None else 0)
                self.error("callback_error", now_ns, exc,
                           f"a {type(msg).__name__} on {topic} stamped {now_ns} ns")
        return guarded

    def level(self) -> bytes:
        if self.errors:
            return DiagnosticStatus.ERROR
        return DiagnosticStatus.WARN if any(self.counts.values()) else DiagnosticStatus.OK

    def _tick(self) -> None:
        self._since_publish_s += CHANGE_POLL_S
        counts = self.counts
        if counts != self._published or self._since_publish_s >= self._period_s - 1e-9:
            self.publish(counts)

    def publish(self, counts: dict[str, int] | None = None) -> None:
        counts = self.counts if counts is None else counts
        node = self._node
        status = DiagnosticStatus()
        status.name = node.get_fully_qualified_name()
        status.hardware_id = "fourws"
        status.level = self.level()
        total = sum(counts.values())
        status.message = ("OK" if not total else
                          f"{total} input(s) rejected" + (f", {self.errors} callback error(s)"
                                                          if self.errors else ""))
        status.values = [KeyValue(key=k, value=str(v)) for k, v in sorted(counts.items())]
        msg = DiagnosticArray()
        msg.header.stamp = node.get_clock().now().to_msg()
        msg.status = [status]
        if self._runtime is not None:
            try:
                rt = self._runtime()
            except Exception as exc:  # noqa: BLE001 - diagnostics never kill the node
                rt = Runtime(ERROR, f"runtime status failed: {type(exc).__name__}: {exc}")
            extra = DiagnosticStatus(name=status.name + RUNTIME_SUFFIX, hardware_id="fourws",
                                     level=rt.level, message=rt.message)
            extra.values = [KeyValue(key=k, value=str(v)) for k, v in rt.values.items()]
            msg.status.append(extra)
        self._pub.publish(msg)
        self._published = dict(counts)
        self._since_publish_s = 0.0
