"""Adapter node: the fourws controllers' input from a car's or simulator's standard messages.

Subscribes ``vehicle/odom`` (nav_msgs/Odometry: pose in the map frame, twist in the body
frame as REP 105 has it), ``vehicle/imu`` (sensor_msgs/Imu: yaw rate, body accelerations) and
``vehicle/joint_states`` (sensor_msgs/JointState: steer angles as positions, wheel spin rates
as velocities; the names are parameters) and publishes ``vehicle/state``
(fourws_msgs/VehicleState), the one input of the MPC, the speed PID and the allocator
(docs/controller-interface.md, "The adapter"). Tyre loads, lateral forces and adhesion, which
no car measures, are estimated from the accelerations
(:mod:`fourws_torque_alloc.core.tyre_estimate`, the realistic bench's estimator) on the
nominal vehicle of ``vehicle_file``. All conversion is in
:mod:`fourws_bringup.core.standard_inputs`; remap the topics to your car's
(``-r vehicle/odom:=/my_car/odom``).

Matching (``sync``): ``exact`` publishes a state once the three messages of one stamp have
arrived (a simulator that stamps them alike, as fourws's plant does); ``latest`` publishes
on every odometry message with the newest IMU and joint messages, each at most
``max_age_s`` older (or newer) than it (a real car's sensors). An input that is not finite
or implausible, or joints that lack a configured name, are rejected, counted and logged
(``/diagnostics``); nothing is published for them. ``wait_for_subscribers``: drop states
until ``vehicle/state`` has that many subscribers (lockstep with a recorder: the plant
publishes a waiting state again).
"""

from __future__ import annotations

from dataclasses import dataclass

from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import Imu, JointState

from fourws_common.conversions import RateLimitedLog, fill_vehicle_state, stamp_to_ns
from fourws_common.health import NodeHealth
from fourws_common.node_main import run_node
from fourws_common.params import param
from fourws_common.qos import qos_of
from fourws_common.ros_params import ParamBinding
from fourws_common.topics import VEHICLE_IMU, VEHICLE_JOINT_STATES, VEHICLE_ODOM, VEHICLE_STATE
from fourws_common.vehicle_info import read_vehicle_file
from fourws_common.wheels import STEER_JOINTS, WHEEL_JOINTS
from fourws_msgs.msg import VehicleState
from fourws_torque_alloc.core.tyre_estimate import EstimatorParams, TyreEstimator

from .core.standard_inputs import JointMap, controller_input

#: stamps of incomplete exact-sync sets kept at most (older ones are dropped)
MAX_PENDING = 64


@dataclass(frozen=True)
class AdapterConfig:
    sync: str = param("exact", "exact: publish when odometry, IMU and joints of one stamp "
                      "have arrived; latest: on each odometry, with the newest IMU and joints",
                      choices=("exact", "latest"))
    max_age_s: float = param(0.05, "latest: the IMU and joint messages may be at most this "
                             "much older (or newer) than the odometry", lo=0.0, hi=10.0, unit="s")
    yaw_rate_source: str = param("imu", "where the yaw rate comes from",
                                 choices=("imu", "odom"))
    steer_front_joints: tuple = param(list(STEER_JOINTS[:1]), "JointState names of the front "
                                      "road-wheel angles (their mean is used)")
    steer_rear_joints: tuple = param(list(STEER_JOINTS[1:]), "JointState names of the rear "
                                     "road-wheel angles (their mean is used)")
    wheel_joints: tuple = param(list(WHEEL_JOINTS), "JointState names of the wheel spin "
                                "joints, FL FR RL RR (velocity in rad/s)")
    vehicle_file: str = param("", "car file of the nominal car for the tyre-force "
                              "estimate (empty: the paper's car)")
    mu_nominal: float = param(0.8, "road adhesion reported to the controllers (not measured)",
                              lo=0.01, hi=3.0)
    wait_for_subscribers: int = param(0, "publish no state until vehicle/state has this many "
                                      "subscribers", lo=0, hi=100)

    def joint_map(self) -> JointMap:
        return JointMap(tuple(self.steer_front_joints), tuple(self.steer_rear_joints),
                        tuple(self.wheel_joints))

    def __post_init__(self) -> None:
        self.joint_map()  # ValueError naming the bad list


class AdapterNode(Node):
    """Wires the standard messages to :func:`controller_input` and publishes the state."""

    def __init__(self) -> None:
        super().__init__("adapter_node")
        self.health = NodeHealth(self)
        self.params = ParamBinding(self, AdapterConfig, on_change=self._apply)
        self._apply(self.params.config)
        self.pub = self.create_publisher(VehicleState, VEHICLE_STATE.ros_name,
                                         qos_of(VEHICLE_STATE))
        self._msg = VehicleState()
        self._msg.header.frame_id = "map"
        self._pending: dict[int, dict[str, object]] = {}
        self._latest: dict[str, object] = {}
        self._wait_log = RateLimitedLog(self.get_logger().info, period_s=5.0)
        for cls, topic, kind in ((Odometry, VEHICLE_ODOM, "odom"), (Imu, VEHICLE_IMU, "imu"),
                                 (JointState, VEHICLE_JOINT_STATES, "joints")):
            self.create_subscription(cls, topic.ros_name, self.health.guard(
                topic.name, lambda m, k=kind: self._on_input(k, m)), qos_of(topic))
        self.get_logger().info(f"adapter: sync {self.params.config.sync}, yaw rate from "
                               f"{self.params.config.yaw_rate_source}")

    def _apply(self, cfg: AdapterConfig) -> None:
        values = read_vehicle_file(cfg.vehicle_file or None)
        self.estimator = TyreEstimator(EstimatorParams.from_mapping(
            {**values, "mu_nominal": cfg.mu_nominal}))
        self.joint_map = cfg.joint_map()

    def _on_input(self, kind: str, msg) -> None:
        stamp = stamp_to_ns(msg.header.stamp)
        if self.params.config.sync == "latest":
            self._latest[kind] = msg
            if kind == "odom":
                self._publish_latest(msg, stamp)
            return
        inputs = self._pending.setdefault(stamp, {})
        inputs[kind] = msg
        if len(inputs) == 3:
            del self._pending[stamp]
            for old in [s for s in self._pending if s < stamp]:
                del self._pending[old]   # a set that never completed: superseded
            self._publish(inputs, stamp)
        elif len(self._pending) > MAX_PENDING:
            oldest = min(self._pending)
            del self._pending[oldest]
            self.health.reject("incomplete_inputs", stamp, f"no complete odometry, IMU and "
                               f"joint set for stamp {oldest} ns: dropped")

    def _publish_latest(self, odom: Odometry, stamp: int) -> None:
        cfg = self.params.config
        inputs: dict[str, object] = {"odom": odom}
        for kind in ("imu", "joints"):
            m = self._latest.get(kind)
            age_s = None if m is None else (stamp - stamp_to_ns(m.header.stamp)) * 1e-9
            if age_s is None or abs(age_s) > cfg.max_age_s:   # ahead of the odometry too
                what = ("none yet" if age_s is None else f"{age_s * 1e3:.0f} ms old" if age_s > 0
                        else f"{-age_s * 1e3:.0f} ms ahead")
                self.health.reject(f"stale_{kind}", stamp, f"odometry at {stamp} ns: {kind} "
                                   f"{what} (limit {cfg.max_age_s * 1e3:.0f} ms): no state")
                return
            inputs[kind] = m
        self._publish(inputs, stamp)

    def _publish(self, inputs: dict, stamp: int) -> None:
        need = self.params.config.wait_for_subscribers
        if need and self.pub.get_subscription_count() < need:
            self._wait_log(stamp, f"waiting for {need} subscribers on "
                           f"{self.pub.topic_name}: state not published yet")
            return
        odom, imu, joints = inputs["odom"], inputs["imu"], inputs["joints"]
        p, q, t = odom.pose.pose.position, odom.pose.pose.orientation, odom.twist.twist
        try:
            s = controller_input(
                (p.x, p.y, p.z, q.x, q.y, q.z, q.w), (t.linear.x, t.linear.y, t.angular.z),
                (imu.angular_velocity.z, imu.linear_acceleration.x, imu.linear_acceleration.y),
                (list(joints.name), list(joints.position), list(joints.velocity)),
                self.joint_map, self.estimator, self.params.config.yaw_rate_source,
                t_s=stamp * 1e-9)
        except ValueError as exc:
            self.health.reject("bad_input", stamp, f"inputs at {stamp} ns rejected: {exc}")
            return
        msg = self._msg
        msg.header.stamp = odom.header.stamp
        self.pub.publish(fill_vehicle_state(msg, s))


def main(args: list[str] | None = None) -> int:
    return run_node(AdapterNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
