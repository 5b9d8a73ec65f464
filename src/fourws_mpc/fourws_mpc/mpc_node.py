"""Runs the MPC on the ROS graph as a node whose parameters reconfigure it online.

Subscribes ``/vehicle/state`` (newest only, :data:`~fourws_common.qos.LATEST_QOS`),
``/reference/trajectory`` and ``/control/wheel_torques`` (the allocator's unmet yaw moment for
the command it answered: the next step starts from the yaw moment delivered,
``MpcController.report_delivered``); publishes ``/control/mpc_command`` and
``/control/mpc_diagnostics`` for every new state, stamped like it. All control logic lives in
``fourws_mpc.core.controller``; this node converts messages, measures the wall time of each
controller step for the diagnostics, and guards its input
(docs/graph.md, "Lifecycle and bad input"):

- a state that is not finite or not physically plausible
  (:func:`fourws_common.input_guard.implausible_fields`) is rejected; nothing reaches the core;
- stamps go through a :class:`~fourws_common.input_guard.StampGate`: an already answered stamp
  is answered again from cache, so the controller's history advances exactly once per step; a
  stamp in the past or far in the future is rejected without becoming the new "last";
- a new run (a new reference trajectory or a confirmed restart of the stamps) resets the
  controller, logged once;
- an exception inside a step is caught and logged with the state that caused it; the node
  answers with its last valid command (``fallback``, solver status ``exception``), so a
  lockstep plant never stalls on it;
- a parameter change is applied to the running controller (``MpcController.update_config``):
  plan, horizons and APCHA history are kept; setting a value it already has changes nothing.

Every rejection is counted, logged at a limited rate and published on ``/diagnostics``, beside
a runtime status (``<node>: runtime``): the last solver status, fallbacks, deadline misses (a
step longer than the control period) and the age of the newest state (WARN when stale).
"""

from __future__ import annotations

import math
import time

from rclpy.node import Node

from fourws_common.health import WARN, NodeHealth, Runtime
from fourws_common.input_guard import state_mu
from fourws_common.node_main import run_node
from fourws_common.qos import qos_of
from fourws_common.ros_params import ParamBinding, vehicle_defaults
from fourws_common.state_input import StateHandlers, StateInput
from fourws_common.topics import (
    MPC_COMMAND,
    MPC_DIAGNOSTICS,
    REFERENCE_TRAJECTORY,
    WHEEL_TORQUES,
)
from fourws_mpc.core.config import MpcConfig
from fourws_mpc.core.controller import MEAS_FIELDS, VehicleSample
from fourws_mpc.core.laws import make_controller, warm_up
from fourws_mpc.core.reference import Reference
from fourws_msgs.msg import (
    MpcCommand,
    MpcDiagnostics,
    ReferenceTrajectory,
    VehicleState,
    WheelTorques,
)

CHECKED_FIELDS = (*MEAS_FIELDS, "mu")


class MpcNode(Node):
    def __init__(self) -> None:
        super().__init__("mpc_node")
        self.params = ParamBinding(self, MpcConfig, on_change=self._on_params,
                                   defaults=vehicle_defaults(self, "mpc_node"))
        self.ctrl = make_controller(self.params.config)
        warm_up(self.params.config)     # the compiled kernels loaded before the first state
        self.ref: Reference | None = None
        self.ref_msg: ReferenceTrajectory | None = None
        self.cached: tuple[MpcCommand, MpcDiagnostics] | None = None
        self.health = NodeHealth(self)
        self.pub_cmd = self.create_publisher(MpcCommand, MPC_COMMAND.ros_name, qos_of(MPC_COMMAND))
        # Built once, every field refilled per step (publish serialises at once); they are
        # also the cached answer to a republished state.
        self._cmd_msg, self._diag_msg = MpcCommand(), MpcDiagnostics()
        self.pub_diag = self.create_publisher(MpcDiagnostics, MPC_DIAGNOSTICS.ros_name,
                                              qos_of(MPC_DIAGNOSTICS))
        self.create_subscription(ReferenceTrajectory, REFERENCE_TRAJECTORY.ros_name,
                                 self.health.guard(REFERENCE_TRAJECTORY.name, self._on_ref),
                                 qos_of(REFERENCE_TRAJECTORY))
        self.create_subscription(WheelTorques, WHEEL_TORQUES.ros_name,
                                 self.health.guard(WHEEL_TORQUES.name, self._on_torques),
                                 qos_of(WHEEL_TORQUES))
        self.state_input = StateInput(
            self, self.health, CHECKED_FIELDS,
            StateHandlers(ready=lambda: self.ref is not None, step=self._step,
                          repeat=self._repeat, held=self._answer_held, reset=self._reset),
            "controller", outputs=(self.pub_cmd, self.pub_diag))
        self.deadline_misses = self._misses_reported = 0
        self.last_status, self.last_solve_ms = "none yet", 0.0
        self.health.runtime(self._runtime)
        self.get_logger().info(f"controller '{self.params.config.controller}'")

    def _runtime(self) -> Runtime:
        """Solver status of the last step, fallbacks, deadline misses (a step that took more
        than the control period), and the input's age (StateInput.runtime)."""
        fallbacks = self.health.counts.get("solver_fallback", 0)
        new_misses = self.deadline_misses - self._misses_reported
        self._misses_reported = self.deadline_misses
        rt = Runtime(values={"solver_status": self.last_status,
                             "last_solve_ms": f"{self.last_solve_ms:.3f}",
                             "fallbacks": str(fallbacks),
                             "deadline_misses": str(self.deadline_misses)})
        problems = []
        if self.cached is not None and self.cached[1].fallback:
            problems.append(f"last step fell back ({self.last_status})")
        if new_misses:
            problems.append(f"{new_misses} step(s) over the {self.params.config.dt_s * 1e3:.0f}"
                            " ms period since the last report")
        if problems:
            rt.level, rt.message = WARN, "; ".join(problems)
        return self.state_input.runtime(rt)

    def _on_params(self, cfg: MpcConfig) -> None:
        old = self.ctrl.cfg
        if cfg.law != old.law:
            self.ctrl = make_controller(cfg)   # another law: a fresh controller
            self.get_logger().warning(f"law changed to '{cfg.law}': controller rebuilt")
        else:
            self.ctrl.update_config(cfg)
        window = (cfg.ref_search_back, cfg.ref_search_ahead)
        if self.ref_msg is not None and window != (old.ref_search_back, old.ref_search_ahead):
            self.ref = self._reference(self.ref_msg)
            self.ctrl.adopt_reference(self.ref)  # keep the nearest-point index
        self.get_logger().info(f"parameters applied to the running controller "
                               f"'{cfg.controller}' (state kept)")

    def _reference(self, msg: ReferenceTrajectory) -> Reference:
        return self.params.config.reference(msg.x, msg.y, msg.yaw, msg.curvature, msg.speed)

    def _on_ref(self, msg: ReferenceTrajectory) -> None:
        try:
            ref = self._reference(msg)
        except (ValueError, FloatingPointError) as exc:
            self.health.reject("reference", 0, f"rejected reference trajectory: {exc}")
            return
        except Exception as exc:  # noqa: BLE001 - a callback never kills the node
            self.health.error("reference_error", 0, exc, f"a reference of {len(msg.x)} points")
            return
        new_run = self.ref is not None
        self.ref, self.ref_msg = ref, msg
        self._reset()
        self.get_logger().info(f"reference with {len(msg.x)} points"
                               + ("; new run: controller reset" if new_run else ""))
        self.state_input.retry_waiting()

    def _on_torques(self, msg: WheelTorques) -> None:
        """The allocator's answer to our last command: start the next step from the yaw
        moment it delivered. Another stamp (an older command) or a non-finite value is
        ignored; the allocator reports its own rejections."""
        unmet = float(msg.unmet_yaw_moment)
        if (self.cached is None or not unmet or not math.isfinite(unmet)
                or msg.header.stamp != self.cached[0].header.stamp
                or not hasattr(self.ctrl, "report_delivered")):
            return
        self.ctrl.report_delivered(self.cached[0].yaw_moment - unmet)

    def _reset(self) -> None:
        self.ctrl.reset()
        self.state_input.reset()
        self.cached = None

    def _repeat(self) -> None:
        if self.cached is not None:
            self.pub_cmd.publish(self.cached[0])
            self.pub_diag.publish(self.cached[1])

    def _step(self, msg: VehicleState, stamp_ns: int, _jumped_ahead: bool) -> None:
        meas = VehicleSample.of(msg)
        t0 = time.perf_counter()
        res = self.ctrl.step(stamp_ns * 1e-9, meas, self.ref, mu=state_mu(msg.mu))
        solve_ms = (time.perf_counter() - t0) * 1e3
        self.last_status, self.last_solve_ms = res.solver_status, solve_ms
        if solve_ms > self.params.config.dt_s * 1e3:
            self.deadline_misses += 1
        cmd, diag = self._cmd_msg, self._diag_msg
        cmd.header = diag.header = msg.header
        cmd.delta_front, cmd.delta_rear = res.delta_front, res.delta_rear
        cmd.yaw_moment = res.yaw_moment
        diag.controller, diag.np, diag.nc = res.controller, int(res.np), int(res.nc)
        diag.q_y, diag.q_phi, diag.r_ddelta, diag.r_dmz = (res.q_y, res.q_phi, res.r_ddelta,
                                                           res.r_dmz)
        diag.lateral_error, diag.heading_error = res.lateral_error, res.heading_error
        diag.e_s, diag.k_e, diag.k_u = res.e_s, res.k_e, res.k_u
        diag.solve_time_ms, diag.solver_status = solve_ms, res.solver_status
        diag.iterations, diag.slack = int(res.iterations), res.slack
        diag.fallback = bool(res.fallback)
        diag.mu_estimate, diag.yaw_moment_bound = res.mu_estimate, res.yaw_moment_bound
        if res.grip_note:
            self.health.reject("mu_estimate", stamp_ns, f"{res.grip_note} at {stamp_ns} ns")
        if res.fallback:
            self.health.reject("solver_fallback", stamp_ns, f"solver '{res.solver_status}' at "
                               f"{stamp_ns} ns: used the previous plan")
        self.cached = (cmd, diag)
        self.pub_cmd.publish(cmd)
        self.pub_diag.publish(diag)

    def _answer_held(self, msg: VehicleState) -> None:
        """After a failed step: the last valid command (zeros before the first), restamped."""
        u = self.ctrl.u_prev
        cmd, diag = self._cmd_msg, self._diag_msg
        cmd.header = diag.header = msg.header
        cmd.delta_front, cmd.delta_rear, cmd.yaw_moment = (float(u[0]), float(u[1]),
                                                           float(u[2]))
        diag.controller = self.params.config.controller
        diag.solver_status, diag.fallback = "exception", True
        diag.solve_time_ms, diag.iterations, diag.slack = 0.0, 0, 0.0
        self.cached = (cmd, diag)
        self.pub_cmd.publish(cmd)
        self.pub_diag.publish(diag)


def main(args: list[str] | None = None) -> int:
    return run_node(MpcNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
