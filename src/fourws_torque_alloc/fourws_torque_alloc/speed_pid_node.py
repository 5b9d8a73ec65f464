"""Computes the total drive force and torque from the speed error, eq. (24), as a ROS node.

Subscribes ``/vehicle/state`` (newest only) and ``/reference/trajectory`` (the speed
profile); publishes ``/control/drive_command`` stamped like the state it answers
(docs/lower-layer.md, "Speed PID", "The nodes"). The reference speed is taken at the path
sample nearest to the car; its feed-forward acceleration is v·dv/ds there. Input guards as in
the MPC node (:mod:`fourws_common.input_guard`): a repeated stamp is answered from cache; a
stamp in the past or far in the future, or a state that is not finite or not plausible, is
rejected (counted, logged at a limited rate, on ``/diagnostics``) and never reaches the
integrator; a new reference or a confirmed restart of the stamps is a new run and resets the
PID; an exception in a step is caught, logged with the state, and answered with the last
valid command. Nothing is published before a reference has arrived. A parameter change keeps
the integrator and filter state.
"""

from __future__ import annotations

from rclpy.node import Node

from fourws_common.health import NodeHealth
from fourws_common.input_guard import check_reference
from fourws_common.node_main import run_node
from fourws_common.path_lookup import SpeedProfile
from fourws_common.qos import qos_of
from fourws_common.ros_params import ParamBinding, vehicle_defaults
from fourws_common.state_input import StateHandlers, StateInput
from fourws_common.topics import DRIVE_COMMAND, REFERENCE_TRAJECTORY
from fourws_msgs.msg import DriveCommand, ReferenceTrajectory, VehicleState
from fourws_torque_alloc.core.pid import SpeedPid, SpeedPidConfig

# The period assumed for the first state of a run or timeline (no previous stamp): 100 Hz.
NOMINAL_DT_S = 0.01


class SpeedPidNode(Node):
    def __init__(self) -> None:
        super().__init__("speed_pid_node")
        self.params = ParamBinding(self, SpeedPidConfig, on_change=self._on_params,
                                   defaults=vehicle_defaults(self, "speed_pid_node"))
        self.pid = SpeedPid(self.params.config)
        self.profile: SpeedProfile | None = None
        self.prev_ns: int | None = None
        self.cached: DriveCommand | None = None
        self.health = NodeHealth(self)
        self.pub = self.create_publisher(DriveCommand, DRIVE_COMMAND.ros_name,
                                         qos_of(DRIVE_COMMAND))
        self._cmd_msg = DriveCommand()  # refilled whole every step; also the cached answer
        self.create_subscription(ReferenceTrajectory, REFERENCE_TRAJECTORY.ros_name,
                                 self.health.guard(REFERENCE_TRAJECTORY.name, self._on_ref),
                                 qos_of(REFERENCE_TRAJECTORY))
        self.state_input = StateInput(
            self, self.health, ("x", "y", "vx"),
            StateHandlers(ready=lambda: self.profile is not None, step=self._step,
                          repeat=self._repeat, held=self._held, reset=self._reset),
            "PID", outputs=(self.pub,))
        self.health.runtime(self.state_input.runtime)

    def _on_params(self, cfg: SpeedPidConfig) -> None:
        self.pid.cfg = cfg  # the integral is in newtons: a gain change is bumpless
        self.get_logger().info("parameters applied (integrator state kept)")

    def _on_ref(self, msg: ReferenceTrajectory) -> None:
        try:
            # the check every node applies to a reference (the MPC and the allocator too)
            check_reference(msg.x, msg.y, msg.yaw, msg.curvature, msg.speed)
            profile = SpeedProfile(msg.x, msg.y, msg.speed)
        except ValueError as exc:
            self.health.reject("reference", 0, f"rejected reference trajectory: {exc}")
            return
        except Exception as exc:  # noqa: BLE001 - a callback never kills the node
            self.health.error("reference_error", 0, exc, f"a reference of {len(msg.x)} points")
            return
        new_run = self.profile is not None
        self.profile = profile
        self._reset()
        self.get_logger().info(f"reference with {profile.speed.size} points, speed "
                               f"{profile.speed.min():.2f}..{profile.speed.max():.2f} m/s"
                               + ("; new run: PID reset" if new_run else ""))
        self.state_input.retry_waiting()

    def _reset(self) -> None:
        self.pid.reset()
        self.state_input.reset()
        self.prev_ns = None
        self.cached = None

    def _repeat(self) -> None:
        if self.cached is not None:
            self.pub.publish(self.cached)

    def _held(self, msg: VehicleState) -> None:
        held = self._cmd_msg  # the last valid command (zeros before the first)
        held.header = msg.header
        self.cached = held
        self.pub.publish(held)

    def _step(self, msg: VehicleState, stamp_ns: int, jumped_ahead: bool) -> None:
        if jumped_ahead:
            self.prev_ns = None  # continue at the nominal period
        dt_s = NOMINAL_DT_S if self.prev_ns is None else (stamp_ns - self.prev_ns) * 1e-9
        v_ref, a_ref = self.profile.at(msg.x, msg.y)
        out = self.pid.step(v_ref, msg.vx, dt_s, a_ref)
        self.prev_ns = stamp_ns
        cmd = self._cmd_msg
        cmd.header, cmd.force, cmd.torque = msg.header, out.force_n, out.torque_nm
        self.cached = cmd
        self.pub.publish(cmd)


def main(args: list[str] | None = None) -> int:
    return run_node(SpeedPidNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
