"""Raw subscriptions taken with their DDS message info, on a thread of their own.

rosbag2 writes a message's ``publish_time`` from the middleware's message info (the
publisher's send time, ``source_timestamp``; docs/bags.md, "Layout") and rclpy hands that info
to a callback only under its Python executors; Jazzy's ``EventsExecutor``, which the fourws
nodes spin (it keeps up at 100 Hz on two loaded cores, the single-threaded executor does not),
calls a two-argument callback with a null argument. So the recorder's subscriptions are kept
out of the executor: :class:`InfoTaker` waits on them in an rcl wait set (``rclpy``'s own
``wait_for_message`` does the same; the wait releases the GIL) and takes every ready
message, serialized, with its info, in a batch.

The subscriptions' event handlers (matched, message lost) stay with the node's executor as
waitables, as :meth:`rclpy.node.Node.create_subscription` adds them.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.subscription import Subscription
from rclpy.type_support import check_is_valid_msg_type

#: ``handler(data, info)``: ``data`` the serialized message, ``info`` rmw's message info
#: (``source_timestamp`` and ``received_timestamp`` in wall ns, ``publication_sequence_number``)
Handler = Callable[[bytes, dict[str, Any]], None]

#: longest wait before the thread looks at its stop flag again (s)
WAIT_S = 0.1


class InfoTaker:
    """Subscriptions of one node that a thread of their own takes with message info."""

    def __init__(self, node: Node) -> None:
        self._node = node
        self._lock = threading.Lock()
        self._subs: list[tuple[Subscription, Handler]] = []
        self._wake = _rclpy.GuardCondition(node.context.handle)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="info_taker", daemon=True)
        self.error: BaseException | None = None

    def subscribe(self, msg_type, topic: str, qos: QoSProfile, handler: Handler,
                  event_callbacks=None) -> Subscription:
        """A raw subscription, taken by this thread; its event handlers go to the node."""
        from rclpy.event_handler import SubscriptionEventCallbacks

        check_is_valid_msg_type(msg_type)
        with self._node.handle:
            impl = _rclpy.Subscription(self._node.handle, msg_type, topic,
                                       qos.get_c_qos_profile())
        sub = Subscription(impl, msg_type, topic, lambda _msg: None,
                           self._node.default_callback_group, qos, True,
                           event_callbacks=event_callbacks or SubscriptionEventCallbacks())
        for event_handler in sub.event_handlers:
            self._node.add_waitable(event_handler)
        with self._lock:
            self._subs.append((sub, handler))
        self._wake.trigger_guard_condition()
        return sub

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread (after the batch it is taking), hand every message still queued to
        its handler, and destroy the subscriptions."""
        self._stop.set()
        try:
            self._wake.trigger_guard_condition()
        except Exception:  # noqa: BLE001 - the context may be gone already
            pass
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join()
        with self._lock:
            subs, self._subs = self._subs, []
        if not self._thread.is_alive():  # what arrived after the thread's last batch
            for sub, handler in subs:
                try:
                    self._take_all(sub, handler, final=True)
                except Exception:  # noqa: BLE001 - the context may be gone already
                    break
        for sub, _ in subs:
            for event_handler in sub.event_handlers:
                self._node.remove_waitable(event_handler)
            sub.destroy()

    def _run(self) -> None:
        wait_set, size = None, -1
        timeout_ns = int(WAIT_S * 1e9)
        try:
            while not self._stop.is_set() and self._node.context.ok():
                with self._lock:
                    subs = list(self._subs)
                if wait_set is None or size != len(subs):
                    size = len(subs)
                    wait_set = _rclpy.WaitSet(size, 1, 0, 0, 0, 0, self._node.context.handle)
                wait_set.clear_entities()
                for sub, _ in subs:
                    wait_set.add_subscription(sub.handle)
                wait_set.add_guard_condition(self._wake)
                wait_set.wait(timeout_ns)
                ready = set(wait_set.get_ready_entities("subscription"))
                for sub, handler in subs:
                    if sub.handle.pointer in ready:
                        self._take_all(sub, handler)
        except BaseException as exc:  # noqa: BLE001 - reported by the node, not lost
            if not self._stop.is_set() and self._node.context.ok():
                self.error = exc

    def _take_all(self, sub: Subscription, handler: Handler, final: bool = False) -> None:
        while final or not self._stop.is_set():
            with sub.handle:
                taken = sub.handle.take_message(sub.msg_type, True)
            if taken is None:
                return
            handler(taken[0], taken[1])
