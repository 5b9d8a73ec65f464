"""Speed PID node: total drive force and torque from the speed error, eq. (24).

Subscribes ``/vehicle/state`` and ``/reference/trajectory`` (the speed profile); publishes
``/control/drive_command`` stamped like the state it answers. The reference speed is taken at
the path sample nearest to the car; its feed-forward acceleration is v·dv/ds there. A state
stamp already answered is answered again with the cached command (the plant republishes a
state while it waits). Non-finite states are rejected and logged; nothing is published for
them, and nothing is published before a reference has arrived.
"""

from __future__ import annotations

from rclpy.node import Node

from fourws_common.conversions import RateLimitedLog, non_finite_fields, stamp_to_ns
from fourws_common.node_main import run_node
from fourws_common.path_lookup import SpeedProfile
from fourws_common.qos import CONTROL_QOS, LATCHED_QOS
from fourws_common.ros_params import ParamBinding
from fourws_msgs.msg import DriveCommand, ReferenceTrajectory, VehicleState
from fourws_torque_alloc.core.pid import SpeedPid, SpeedPidConfig

# The period assumed for the first state (no previous stamp): the graph's 100 Hz.
NOMINAL_DT_S = 0.01


class SpeedPidNode(Node):
    def __init__(self) -> None:
        super().__init__("speed_pid_node")
        self.params = ParamBinding(self, SpeedPidConfig, on_change=self._on_params)
        self.pid = SpeedPid(self.params.config)
        self.profile: SpeedProfile | None = None
        self.last_stamp_ns: int | None = None
        self.cached: DriveCommand | None = None
        self.reject_log = RateLimitedLog(self.get_logger().warning)
        self.wait_log = RateLimitedLog(self.get_logger().warning, period_s=5.0)
        self.pub = self.create_publisher(DriveCommand, "/control/drive_command", CONTROL_QOS)
        self._cmd_msg = DriveCommand()  # refilled whole every step; also the cached answer
        self.create_subscription(ReferenceTrajectory, "/reference/trajectory", self._on_ref,
                                 LATCHED_QOS)
        self.create_subscription(VehicleState, "/vehicle/state", self._on_state, CONTROL_QOS)

    def _on_params(self, cfg: SpeedPidConfig) -> None:
        integral = self.pid.integral_n
        self.pid = SpeedPid(cfg)
        self.pid.reset(integral)

    def _on_ref(self, msg: ReferenceTrajectory) -> None:
        try:
            profile = SpeedProfile(msg.x, msg.y, msg.speed)
        except ValueError as exc:
            self.get_logger().error(f"rejected reference trajectory: {exc}")
            return
        self.profile = profile
        self.get_logger().info(f"reference with {profile.speed.size} points, speed "
                               f"{profile.speed.min():.2f}..{profile.speed.max():.2f} m/s")

    def _on_state(self, msg: VehicleState) -> None:
        stamp_ns = stamp_to_ns(msg.header.stamp)
        if stamp_ns == self.last_stamp_ns and self.cached is not None:
            self.pub.publish(self.cached)
            return
        bad = non_finite_fields(msg, ("x", "y", "vx"))
        if bad:
            self.reject_log(stamp_ns, f"rejected vehicle state with non-finite {bad}")
            return
        if self.profile is None:
            self.wait_log(stamp_ns, "no reference trajectory yet: not answering states")
            return
        dt_s = (NOMINAL_DT_S if self.last_stamp_ns is None
                else (stamp_ns - self.last_stamp_ns) * 1e-9)
        if dt_s <= 0.0:
            self.reject_log(stamp_ns, f"rejected state stamped {stamp_ns} ns: not after the "
                            f"last one ({self.last_stamp_ns} ns)")
            return
        v_ref, a_ref = self.profile.at(msg.x, msg.y)
        out = self.pid.step(v_ref, msg.vx, dt_s, a_ref)
        cmd = self._cmd_msg
        cmd.header, cmd.force, cmd.torque = msg.header, out.force_n, out.torque_nm
        self.last_stamp_ns, self.cached = stamp_ns, cmd
        self.pub.publish(cmd)


def main(args: list[str] | None = None) -> int:
    return run_node(SpeedPidNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
