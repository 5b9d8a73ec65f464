"""``sync: latest`` for a controller's state input: answer the newest state, skip a backlog.

In realtime a controller that fell behind (a stall, a slow step) must act on the newest
state, not work through the states that queued meanwhile (docs/graph.md, "Timing"). With
``sync: latest`` the subscription (best effort, keep-last 1: ``fourws_common.state_input``)
delivers what the transport still holds at once, and its callback only keeps the newest
message (cheap: a backlog drains at once); a 1 ms steady-clock timer hands it to the node's
handler; a state replaced before it was handled is counted (``skipped_state`` on
/diagnostics). With ``sync: lockstep`` every state is handled as it arrives (one state is in
flight per step, and the answer is keyed by its stamp).
"""

from __future__ import annotations

from collections.abc import Callable

from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from fourws_common.conversions import stamp_to_ns
from fourws_common.health import NodeHealth

#: Steady-clock period (s) at which the newest state is handled in ``latest`` mode.
LATEST_PERIOD_S = 0.001


class LatestInput:
    """Dispatches state messages to ``handle`` by the node's ``sync`` mode."""

    def __init__(self, node: Node, handle: Callable[[object], None], health: NodeHealth,
                 sync: str = "lockstep") -> None:
        self._node, self._handle, self._health = node, handle, health
        self._msg = None
        self._timer = None
        self.sync = ""
        self.set_sync(sync)

    def set_sync(self, sync: str) -> None:
        if sync == self.sync:
            return
        self.sync = sync
        if sync == "latest" and self._timer is None:
            self._timer = self._node.create_timer(
                LATEST_PERIOD_S, self._tick, clock=Clock(clock_type=ClockType.STEADY_TIME))
        elif sync != "latest" and self._timer is not None:
            self._timer.cancel()
            self._node.destroy_timer(self._timer)
            self._timer = None
            self._tick()  # nothing held is lost

    def offer(self, msg) -> None:
        """The subscription callback."""
        if self.sync != "latest":
            self._handle(msg)
            return
        if self._msg is not None:
            stamp = stamp_to_ns(self._msg.header.stamp)
            self._health.reject("skipped_state", stamp, f"skipped the state at {stamp} ns: "
                                "a newer one arrived before it was handled")
        self._msg = msg

    def _tick(self) -> None:
        msg, self._msg = self._msg, None
        if msg is not None:
            self._handle(msg)
