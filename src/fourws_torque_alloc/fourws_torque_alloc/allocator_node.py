"""Allocates the four in-wheel motor torques from the drive demand and the yaw moment, as a node.

Subscribes ``/vehicle/state`` (per-wheel Fz, Fy, μ with ``tyre_forces: oracle``; the measured
a_x, a_y with ``tyre_forces: estimated``, ``core.tyre_estimate.TyreData``),
``/control/drive_command`` (total torque T) and ``/control/mpc_command`` (yaw moment Mz);
publishes ``/control/wheel_torques`` (docs/lower-layer.md, "The nodes").

- ``sync: lockstep`` (default): publishes once per step, when it holds all three inputs with
  the same stamp, stamped with it; a stamp already answered is answered again from cache.
- ``sync: latest``: publishes on every drive command with the latest state and yaw moment.

Bad input (NaN/inf, absurd demand, a wheel in the air the core cannot serve) never gives a
non-finite torque: the core raises (or the state fails
:func:`fourws_common.input_guard.implausible_fields`), the input is rejected and logged, and
the last valid torques are published again with the new stamp so the plant never stalls. An
input stamped in the past or far in the future is dropped with a count (``/diagnostics``),
never adopted as the new "last". A new reference trajectory (a new run) or a confirmed
restart of the state stamps clears every held input and the last valid torques.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields

import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from fourws_common.conversions import RateLimitedLog, stamp_to_ns
from fourws_common.health import NodeHealth, Runtime, with_input_age
from fourws_common.input_guard import (
    MAX_STAMP_JUMP_NS,
    TIMELINE_QUIET_NS,
    Stamp,
    StampGate,
    check_reference,
    implausible_fields,
)
from fourws_common.node_main import run_node
from fourws_common.params import param
from fourws_common.qos import LATEST_QOS, qos_of
from fourws_common.ros_params import ParamBinding, vehicle_defaults
from fourws_common.state_input import MATCH_RETRY_PERIOD_S
from fourws_common.topics import (
    DRIVE_COMMAND,
    MPC_COMMAND,
    REFERENCE_TRAJECTORY,
    VEHICLE_STATE,
    WHEEL_TORQUES,
)
from fourws_msgs.msg import (
    DriveCommand,
    MpcCommand,
    ReferenceTrajectory,
    VehicleState,
    WheelTorques,
)
from fourws_torque_alloc.core.allocation import AllocatorConfig, TorqueAllocator
from fourws_torque_alloc.core.slip_control import WheelMotion
from fourws_torque_alloc.core.tyre_estimate import TyreData

#: the state fields the wheel-slip limiter reads
SLIP_FIELDS = ("wheel_speed", "vx", "vy", "yaw_rate", "steer_front", "steer_rear")


@dataclass(frozen=True)
class AllocatorNodeConfig(AllocatorConfig):
    sync: str = param("lockstep", "lockstep: answer each stamp once all inputs hold it; "
                      "latest: answer every drive command with the latest inputs",
                      choices=("lockstep", "latest"))
    wait_for_subscribers: int = param(
        0, "lockstep: answer only once /control/wheel_torques has matched this many "
        "subscriptions (fourws run sets the graph's count, the recorder included); the plant "
        "asks again every republish period; 0: answer at once", lo=0, hi=100)

    def core(self) -> AllocatorConfig:
        return AllocatorConfig(**{f.name: getattr(self, f.name)
                                  for f in fields(AllocatorConfig)})


#: Inputs held per topic while waiting for the other two of a stamp (lockstep).
MAX_HELD = 100


class AllocatorNode(Node):
    def __init__(self) -> None:
        super().__init__("allocator_node")
        self.params = ParamBinding(self, AllocatorNodeConfig, on_change=self._on_params,
                                   defaults=vehicle_defaults(self, "allocator_node"))
        self.alloc = TorqueAllocator(self.params.config.core())
        self.tyre_data = TyreData(self.params.config)
        self.states: dict[int, VehicleState] = {}
        self.drives: dict[int, DriveCommand] = {}
        self.mpcs: dict[int, MpcCommand] = {}
        self.last_stamp_ns: int | None = None
        self.cached: WheelTorques | None = None
        self.last_valid = np.zeros(4)
        self.gate = StampGate(MAX_STAMP_JUMP_NS, TIMELINE_QUIET_NS)  # on the state stamps
        self.health = NodeHealth(self)
        self._last_input: float | None = None
        self._unmet = (0.0, 0.0)            # the last step's unmet F_x (N) and M_z (N·m)
        self.health.runtime(lambda: with_input_age(
            Runtime(values={"method": self.params.config.method,
                            "unmet_fx_n": f"{self._unmet[0]:.1f}",
                            "unmet_mz_nm": f"{self._unmet[1]:.1f}"}),
            None if self._last_input is None else time.monotonic() - self._last_input,
            VEHICLE_STATE.name))
        self._match_log = RateLimitedLog(self.get_logger().info, period_s=5.0)
        self._match_timer = None  # retries held inputs until the outputs have matched
        self.pub = self.create_publisher(WheelTorques, WHEEL_TORQUES.ros_name,
                                         qos_of(WHEEL_TORQUES))
        self._out_msg = WheelTorques()  # refilled whole every step; also the cached answer
        self.create_subscription(ReferenceTrajectory, REFERENCE_TRAJECTORY.ros_name,
                                 self.health.guard(REFERENCE_TRAJECTORY.name, self._on_ref),
                                 qos_of(REFERENCE_TRAJECTORY))
        self.create_subscription(VehicleState, VEHICLE_STATE.ros_name,
                                 self.health.guard(VEHICLE_STATE.name, self._on_state),
                                 LATEST_QOS)
        self.create_subscription(DriveCommand, DRIVE_COMMAND.ros_name,
                                 lambda m: self._on_input(self.drives, m), qos_of(DRIVE_COMMAND))
        self.create_subscription(MpcCommand, MPC_COMMAND.ros_name,
                                 lambda m: self._on_input(self.mpcs, m), qos_of(MPC_COMMAND))
        self.get_logger().info(f"allocation method '{self.params.config.method}'")

    def _on_params(self, cfg: AllocatorNodeConfig) -> None:
        if cfg.core() != self.alloc.cfg:
            self.alloc = TorqueAllocator(cfg.core())
            self.tyre_data = TyreData(cfg)

    def _on_ref(self, msg: ReferenceTrajectory) -> None:
        """A new reference is a new run: forget every held input and answer. A reference the
        controllers would refuse is no new run."""
        try:
            check_reference(msg.x, msg.y, msg.yaw, msg.curvature, msg.speed)
        except ValueError as exc:
            self.health.reject("reference", 0, f"rejected reference trajectory: {exc}")
            return
        had = self.last_stamp_ns is not None
        self._reset()
        if had:
            self.get_logger().info("new run (reference trajectory): allocator reset")

    def _reset(self) -> None:
        for d in (self.states, self.drives, self.mpcs):
            d.clear()
        self.last_stamp_ns, self.cached = None, None
        self.last_valid = np.zeros(4)
        self.gate.reset()
        self.alloc = TorqueAllocator(self.params.config.core())

    def _on_state(self, msg: VehicleState) -> None:
        self._last_input = time.monotonic()
        stamp_ns = stamp_to_ns(msg.header.stamp)
        verdict = self.gate.check(stamp_ns, time.monotonic_ns())
        if verdict in (Stamp.PAST, Stamp.FUTURE):
            self.health.reject(f"{verdict.value}_stamp", stamp_ns,
                               f"rejected state stamped {stamp_ns} ns: in the "
                               f"{verdict.value} of the last one ({self.gate.last_ns} ns)")
            return
        if verdict is Stamp.JUMPED:
            self.get_logger().warning(f"stamps jumped to {stamp_ns} ns: new timeline, "
                                      "allocator reset")
            self._reset()
            self.gate.check(stamp_ns, time.monotonic_ns())
        self._on_input(self.states, msg)

    def _on_input(self, store: dict, msg) -> None:
        try:
            self._take(store, msg)
        except Exception as exc:  # noqa: BLE001 - a callback never kills the node
            stamp_ns = stamp_to_ns(msg.header.stamp)
            self.health.error("callback_error", stamp_ns, exc,
                              f"a {type(msg).__name__} stamped {stamp_ns} ns")

    def _take(self, store: dict, msg) -> None:
        stamp_ns = stamp_to_ns(msg.header.stamp)
        if self.params.config.sync == "latest":
            store.clear()
            store[stamp_ns] = msg
            if store is self.drives and self.states and self.mpcs:
                self._answer(stamp_ns, next(iter(self.states.values())), msg,
                             next(iter(self.mpcs.values())))
            return
        if stamp_ns == self.last_stamp_ns and self.cached is not None:
            if store is self.drives:
                self.pub.publish(self.cached)
            return
        if self.last_stamp_ns is not None and stamp_ns < self.last_stamp_ns:
            self.health.reject("past_stamp", stamp_ns, f"dropped a {type(msg).__name__} "
                               f"stamped {stamp_ns} ns: already past step {self.last_stamp_ns}")
            return
        store[stamp_ns] = msg
        if len(store) > MAX_HELD:  # strays that no state will ever match: the one farthest
            ref = self.gate.last_ns if self.gate.last_ns is not None else stamp_ns
            far = max(store, key=lambda k: abs(k - ref))   # from the newest state goes
            del store[far]
            self.health.reject("stray_input", far, f"dropped a {type(msg).__name__} "
                               f"stamped {far} ns: {MAX_HELD} held and none matched by a "
                               f"state (the newest is {ref} ns)")
        self._answer_held(stamp_ns)

    def _answer_held(self, stamp_ns: int) -> None:
        """Answer ``stamp_ns`` if all three inputs for it are held and the outputs matched."""
        if not (stamp_ns in self.states and stamp_ns in self.drives and stamp_ns in self.mpcs):
            return
        if not self._outputs_matched():
            if self._match_timer is None:
                self._match_timer = self.create_timer(
                    MATCH_RETRY_PERIOD_S, self._retry_matched,
                    clock=Clock(clock_type=ClockType.STEADY_TIME))
            return
        self._answer(stamp_ns, self.states.pop(stamp_ns), self.drives.pop(stamp_ns),
                     self.mpcs.pop(stamp_ns))
        for d in (self.states, self.drives, self.mpcs):
            for k in [k for k in d if k <= stamp_ns]:
                del d[k]

    def _retry_matched(self) -> None:
        """The timer of inputs held for unmatched outputs: answer the newest complete stamp
        once the outputs have matched (or stop when nothing is held complete any more)."""
        complete = [k for k in self.states if k in self.drives and k in self.mpcs]
        if complete and not self._outputs_matched():
            return
        self._match_timer.cancel()
        self.destroy_timer(self._match_timer)
        self._match_timer = None
        if complete:
            self._answer_held(max(complete))

    def _outputs_matched(self) -> bool:
        """Lockstep, until the first answer of a run: /control/wheel_torques has matched
        ``wait_for_subscribers`` subscriptions (a subscriber that leaves mid-run never
        stalls the allocator). Held inputs wait and are answered as soon as it has (checked
        every ``MATCH_RETRY_PERIOD_S``; the plant's republished state retries too)."""
        need = self.params.config.wait_for_subscribers
        if self.last_stamp_ns is not None or not need:
            return True
        have = self.pub.get_subscription_count()
        if have < need:
            self._match_log(0, f"waiting for subscribers on {WHEEL_TORQUES.name} "
                            f"({have}/{need}): not answering yet")
        return have >= need

    def _answer(self, stamp_ns: int, state: VehicleState, drive: DriveCommand,
                mpc: MpcCommand) -> None:
        out = self._out_msg
        out.header = drive.header
        out.allocation = self.params.config.method
        out.unmet_torque = out.unmet_yaw_moment = 0.0
        try:
            used = ("fz", "fy", "mu") if self.tyre_data.estimator is None else ("ax", "ay")
            slip = self.params.config.slip_control
            bad = implausible_fields(state, used + (SLIP_FIELDS if slip else ()))
            if bad:
                raise ValueError(f"implausible state {', '.join(bad)}")
            fz, fy, mu = self.tyre_data.of(state)
            res = self.alloc.allocate(drive.torque, mpc.yaw_moment, fz, fy, mu,
                                      WheelMotion.of(state) if slip else None)
            torque = np.asarray(res.torque_nm, dtype=float)
            if not np.all(np.isfinite(torque)):
                raise ValueError(f"allocation gave non-finite torques {torque.tolist()}")
            out.unmet_torque = float(res.unmet_torque_nm)
            out.unmet_yaw_moment = float(res.unmet_yaw_moment_nm)
            self._unmet = (out.unmet_torque / self.params.config.wheel_radius_m,
                           out.unmet_yaw_moment)
            self.last_valid = torque
        except (ValueError, ArithmeticError) as exc:
            self.health.reject("inputs", stamp_ns, f"rejected inputs at {stamp_ns} ns ({exc}); "
                               "holding the last valid torques")
            torque = self.last_valid
            out.allocation = f"{out.allocation}:held"
        out.torque = torque.copy()
        self.last_stamp_ns, self.cached = stamp_ns, out
        self.pub.publish(out)


def main(args: list[str] | None = None) -> int:
    return run_node(AllocatorNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
