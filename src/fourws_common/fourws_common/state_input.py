"""The controllers' one /vehicle/state input pipeline (MPC and speed PID alike).

Each state goes through, in this order (docs/graph.md, "Lifecycle and bad input", "Timing"):

1. the ``sync`` mode (:class:`~fourws_common.latest_input.LatestInput`, parameter ``sync`` of
   :class:`~fourws_common.input_guard.InputConfig`), which also sets the subscription's QoS:
   ``lockstep`` reliable keep-last 1 (``LATEST_QOS``: every state of a step), ``latest`` best
   effort keep-last 1 (``NEWEST_QOS``): a state lost while the node stalled is not repaired, so
   it never holds back the newest one;
2. plausibility (:func:`~fourws_common.input_guard.implausible_fields` on the fields the core
   reads): an implausible state is rejected and counted;
3. a reference must have arrived (else the state is not answered; logged every 5 s). The
   newest state that waited for it is kept and answered by :meth:`StateInput.retry_waiting`
   when the reference comes (state and reference are separate DDS writers with no order
   between them, and a lockstep bag replay does not publish its first state twice);
4. the stamp rule (:class:`~fourws_common.input_guard.StampGate`): a repeat is answered from
   the cache, a stamp in the past or the far future is rejected, a confirmed jump back is a
   new run (the node's core is reset), a confirmed jump ahead continues;
5. the node's outputs must be matched (lockstep, ``wait_for_subscribers``, until the first
   answer of a run): the first state is not answered until the node's ``outputs``
   publishers have matched that many subscriptions in total; the newest state that waited is
   answered as soon as they have (checked every ``MATCH_RETRY_PERIOD_S``);
6. the node's step; an exception in it is caught, logged with the state, and answered with
   the node's held output. A callback never kills the node.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from fourws_common.conversions import RateLimitedLog, stamp_to_ns
from fourws_common.health import NodeHealth, Runtime, with_input_age
from fourws_common.input_guard import (
    MAX_STAMP_JUMP_NS,
    TIMELINE_QUIET_NS,
    InputConfig,
    Stamp,
    StampGate,
    implausible_fields,
)
from fourws_common.latest_input import LatestInput
from fourws_common.qos import LATEST_QOS, NEWEST_QOS
from fourws_common.ros_params import ParamBinding
from fourws_common.topics import VEHICLE_STATE
from fourws_msgs.msg import VehicleState

#: Wall period (s, steady clock) at which a state held back for unmatched outputs is retried.
MATCH_RETRY_PERIOD_S = 0.01


@dataclass(frozen=True)
class StateHandlers:
    """What a node does at each outcome of the pipeline."""

    ready: Callable[[], bool]                 # a reference has arrived
    step: Callable[[Any, int, bool], None]    # (state, stamp_ns, after a jump ahead)
    repeat: Callable[[], None]                # answer a repeated stamp from the cache
    held: Callable[[Any], None]               # answer after a failed step
    reset: Callable[[], None]                 # new run: reset the node's core


class StateInput:
    """Subscribes ``node`` to /vehicle/state through the pipeline of the module docstring.

    ``checked``: the state fields the core reads; ``core_name``: what a reset resets, for
    the log ("controller", "PID").
    """

    def __init__(self, node: Node, health: NodeHealth, checked: Sequence[str],
                 handlers: StateHandlers, core_name: str, outputs: Sequence[Any] = ()) -> None:
        self._node, self._health, self._h = node, health, handlers
        self._outputs = tuple(outputs)
        self._outputs_matched = False  # checked until the first answer of a run only
        self._checked = tuple(checked)
        self._core_name = core_name
        # the newest plausible state that came before a reference or the outputs' matches
        self._waiting: Any = None
        self._match_timer = None  # retries the waiting state until the outputs have matched
        self._last_input: float | None = None  # steady time of the newest state received
        self.gate = StampGate(MAX_STAMP_JUMP_NS, TIMELINE_QUIET_NS)
        self._wait_log = RateLimitedLog(node.get_logger().info, period_s=5.0)
        self._match_log = RateLimitedLog(node.get_logger().info, period_s=5.0)
        self.latest = LatestInput(node, health.guard(VEHICLE_STATE.name, self._on_state),
                                  health)
        self._offer = health.guard(VEHICLE_STATE.name, self.latest.offer)
        self._sub: Any = None
        self._sub_sync = ""
        self.inputs = ParamBinding(node, InputConfig, on_change=self._apply_sync)
        self._apply_sync(self.inputs.config)

    def _apply_sync(self, cfg: InputConfig) -> None:
        """The ``sync`` mode: dispatch (LatestInput) and the state subscription's QoS
        (module docstring, step 1); the subscription is made again when the mode changes."""
        self.latest.set_sync(cfg.sync)
        if cfg.sync == self._sub_sync:
            return
        if self._sub is not None:
            self._node.destroy_subscription(self._sub)
        self._sub = self._node.create_subscription(
            VehicleState, VEHICLE_STATE.ros_name, self._offer,
            NEWEST_QOS if cfg.sync == "latest" else LATEST_QOS)
        self._sub_sync = cfg.sync

    def reset(self) -> None:
        """Forget the stamps (a new run starts from any stamp) and check the outputs' matches
        again before the new run's first answer."""
        self.gate.reset()
        self._outputs_matched = False

    def retry_waiting(self) -> None:
        """Answer the newest state that arrived before the node was ready (call when the
        reference arrives); nothing if none waited."""
        msg, self._waiting = self._waiting, None
        if msg is not None and self._h.ready():
            self._on_state(msg)

    def _retry_matched(self) -> None:
        """The timer of a state held back for unmatched outputs: answer it once they have
        matched (the timer ends then, or when no state waits any more)."""
        if self._waiting is not None and self._unmatched():
            return
        self._match_timer.cancel()
        self._node.destroy_timer(self._match_timer)
        self._match_timer = None
        self.retry_waiting()

    def _unmatched(self) -> list[str]:
        """Output topics with fewer matched subscriptions than their count (lockstep), until
        the first answer of a run: a subscriber that leaves mid-run never stalls the node."""
        if self._outputs_matched:
            return []
        cfg = self.inputs.config
        need = cfg.wait_for_subscribers if cfg.sync == "lockstep" else 0
        counts = [pub.get_subscription_count() for pub in self._outputs] if need else []
        if sum(counts) >= need:
            self._outputs_matched = True
            return []
        return [f"{pub.topic_name} ({n})" for pub, n in zip(self._outputs, counts, strict=True)]

    def input_age_s(self) -> float | None:
        """Steady seconds since the newest state arrived (None before the first)."""
        return None if self._last_input is None else time.monotonic() - self._last_input

    def runtime(self, extra: Runtime | None = None) -> Runtime:
        """The node's runtime status (``fourws_common.health``): ``extra`` (the node's own
        condition, OK if None) with the input's age, WARN when it is stale."""
        return with_input_age(extra or Runtime(), self.input_age_s(), VEHICLE_STATE.name)

    def _on_state(self, msg: Any) -> None:
        self._last_input = time.monotonic()
        stamp_ns = stamp_to_ns(msg.header.stamp)
        bad = implausible_fields(msg, self._checked)
        if bad:
            self._health.reject("implausible_state", stamp_ns, f"rejected vehicle state at "
                                f"{stamp_ns} ns: {', '.join(bad)}")
            return
        if not self._h.ready():
            self._waiting = msg
            self._wait_log(stamp_ns, "no reference trajectory yet: not answering states")
            return
        self._waiting = None
        unmatched = self._unmatched()
        if unmatched:
            self._match_log(stamp_ns, f"waiting for {self.inputs.config.wait_for_subscribers} "
                            f"matched subscriptions in all on {', '.join(unmatched)}: not "
                            "answering states yet")
            self._waiting = msg
            if self._match_timer is None:
                self._match_timer = self._node.create_timer(
                    MATCH_RETRY_PERIOD_S, self._retry_matched,
                    clock=Clock(clock_type=ClockType.STEADY_TIME))
            return
        prev_ns = self.gate.last_ns
        verdict = self.gate.check(stamp_ns, time.monotonic_ns())
        if verdict is Stamp.REPEAT:
            self._h.repeat()
            return
        if verdict in (Stamp.PAST, Stamp.FUTURE):
            self._health.reject(f"{verdict.value}_stamp", stamp_ns,
                                f"rejected state stamped {stamp_ns} ns: in the "
                                f"{verdict.value} of the last one ({self.gate.last_ns} ns)")
            return
        jumped_ahead = False
        log = self._node.get_logger()
        if verdict is Stamp.JUMPED and stamp_ns < prev_ns:
            log.warning(f"stamps went back to {stamp_ns} ns: new run, {self._core_name} reset")
            self._h.reset()
            self.gate.reset()
            self.gate.check(stamp_ns, time.monotonic_ns())
        elif verdict is Stamp.JUMPED:
            log.warning(f"stamps jumped ahead to {stamp_ns} ns (from {prev_ns} ns): continuing")
            jumped_ahead = True
        try:
            self._h.step(msg, stamp_ns, jumped_ahead)
        except Exception as exc:  # noqa: BLE001 - a callback never kills the node
            fields = ", ".join(f"{k}={getattr(msg, k):.6g}" for k in self._checked
                               if isinstance(getattr(msg, k), float))
            self._health.error("step_error", stamp_ns, exc,
                               f"the state at {stamp_ns} ns ({fields})")
            self._h.held(msg)
