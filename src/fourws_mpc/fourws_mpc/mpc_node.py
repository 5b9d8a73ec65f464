"""MPC node: the online parameter-reconfigured MPC on the ROS graph.

Subscribes ``/vehicle/state`` and ``/reference/trajectory``; publishes
``/control/mpc_command`` and ``/control/mpc_diagnostics`` for every new state, stamped like
it. All control logic lives in ``fourws_mpc.core.controller``; this node converts messages,
measures the wall time of each controller step for the diagnostics, and handles bad input:
a state with NaN/inf is rejected and logged (nothing is published for it); a state stamp
already answered (the plant republishes while it waits) is answered again from cache, so the
controller's internal history (APCHA, warm start) advances exactly once per step.
"""

from __future__ import annotations

import time

import numpy as np
from rclpy.node import Node

from fourws_common.conversions import RateLimitedLog, non_finite_fields, stamp_to_ns
from fourws_common.node_main import run_node
from fourws_common.qos import CONTROL_QOS, LATCHED_QOS
from fourws_common.ros_params import ParamBinding
from fourws_mpc.core.controller import MpcConfig, MpcController, VehicleSample
from fourws_mpc.core.reference import Reference
from fourws_msgs.msg import MpcCommand, MpcDiagnostics, ReferenceTrajectory, VehicleState

STATE_FIELDS = ("x", "y", "yaw", "vx", "vy", "yaw_rate")


class MpcNode(Node):
    def __init__(self) -> None:
        super().__init__("mpc_node")
        self.params = ParamBinding(self, MpcConfig, on_change=self._on_params)
        self.ctrl = MpcController(self.params.config)
        self.ref: Reference | None = None
        self.last_stamp_ns: int | None = None
        self.cached: tuple[MpcCommand, MpcDiagnostics] | None = None
        self.reject_log = RateLimitedLog(self.get_logger().warning)
        self.wait_log = RateLimitedLog(self.get_logger().warning, period_s=5.0)
        self.fallback_log = RateLimitedLog(self.get_logger().warning)
        self.pub_cmd = self.create_publisher(MpcCommand, "/control/mpc_command", CONTROL_QOS)
        # Built once, every field refilled per step (publish serialises at once); they are
        # also the cached answer to a republished state.
        self._cmd_msg, self._diag_msg = MpcCommand(), MpcDiagnostics()
        self.pub_diag = self.create_publisher(MpcDiagnostics, "/control/mpc_diagnostics",
                                              CONTROL_QOS)
        self.create_subscription(ReferenceTrajectory, "/reference/trajectory", self._on_ref,
                                 LATCHED_QOS)
        self.create_subscription(VehicleState, "/vehicle/state", self._on_state, CONTROL_QOS)
        self.get_logger().info(f"controller '{self.params.config.controller}'")

    def _on_params(self, cfg: MpcConfig) -> None:
        self.ctrl = MpcController(cfg)
        self.get_logger().info(f"parameters changed: controller '{cfg.controller}' rebuilt")

    def _on_ref(self, msg: ReferenceTrajectory) -> None:
        try:
            self.ref = Reference.from_arrays(
                np.asarray(msg.x), np.asarray(msg.y), np.asarray(msg.yaw),
                np.asarray(msg.curvature), np.asarray(msg.speed))
        except ValueError as exc:
            self.get_logger().error(f"rejected reference trajectory: {exc}")
            return
        self.get_logger().info(f"reference with {len(msg.x)} points")

    def _on_state(self, msg: VehicleState) -> None:
        stamp_ns = stamp_to_ns(msg.header.stamp)
        if stamp_ns == self.last_stamp_ns and self.cached is not None:
            self.pub_cmd.publish(self.cached[0])
            self.pub_diag.publish(self.cached[1])
            return
        bad = non_finite_fields(msg, STATE_FIELDS)
        if bad:
            self.reject_log(stamp_ns, f"rejected vehicle state at {stamp_ns} ns with "
                            f"non-finite {bad}")
            return
        if self.ref is None:
            self.wait_log(stamp_ns, "no reference trajectory yet: not answering states")
            return
        meas = VehicleSample(**{k: float(getattr(msg, k)) for k in STATE_FIELDS})
        t0 = time.perf_counter()
        mu = float(np.mean(msg.mu))
        res = self.ctrl.step(stamp_ns * 1e-9, meas, self.ref,
                             mu=mu if np.isfinite(mu) and mu > 0.0 else None)
        solve_ms = (time.perf_counter() - t0) * 1e3
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
        if res.fallback:
            self.fallback_log(stamp_ns, f"solver '{res.solver_status}' at {stamp_ns} ns: "
                              "used the previous plan")
        self.last_stamp_ns, self.cached = stamp_ns, (cmd, diag)
        self.pub_cmd.publish(cmd)
        self.pub_diag.publish(diag)


def main(args: list[str] | None = None) -> int:
    return run_node(MpcNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
