"""adapter_node: the controllers driven from a car's standard messages.

- The realistic paper scenario (noise, one period of delay, 40 ms dead time, estimated
  tyre data) run through the adapter (plant -> Odometry, Imu, JointState -> adapter_node ->
  controllers) gives the direct path's result within 1 µm of max and RMS |e_Y|, step for step
  (the only difference is the heading's round trip through a quaternion, ~1e-16 rad).
- The adapter alone rejects what it cannot use, counts it on /diagnostics and publishes no
  NaN: a non-finite odometry, joints without a configured name, and (``sync: latest``) an IMU
  older than ``max_age_s``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rclpy.duration import Duration
from sensor_msgs.msg import Imu, JointState

from fourws_bringup.bag.run_data import read_run
from fourws_bringup.core.conditions import load_condition
from fourws_bringup.supervisor import NodeSpec
from fourws_bringup.workflow import run_and_score
from fourws_common.conversions import ns_to_stamp, stamp_to_ns
from fourws_common.qos import CONTROL_QOS, DIAGNOSTICS_QOS
from fourws_common.resources import config_dir
from fourws_common.wheels import JOINT_NAMES
from fourws_msgs.msg import VehicleState

pytestmark = pytest.mark.integration

#: what "close to the direct path" means: the same run up to the quaternion round-off
TOLERANCE_M = 1e-6


@pytest.mark.slow
def test_the_realistic_paper_scenario_through_the_adapter_matches_the_direct_path(tmp_path):
    cond = load_condition("realistic", 0)
    direct = run_and_score("dlc_60_mu05", "improved", tmp_path / "direct", plots=False,
                           progress=False, condition=cond)
    via = run_and_score("dlc_60_mu05", "improved", tmp_path / "adapter", plots=False,
                        progress=False, condition=cond, via_adapter=True)
    assert direct["completed"] and via["completed"], (direct["reason"], via["reason"])
    assert via["via_adapter"] and via["input_rejections"] == {} and via["missing_steps"] == 0
    assert via["steps"] == direct["steps"] > 1000
    for key in ("max_abs_lateral_error_m", "rmse_lateral_error_m"):
        assert abs(via[key] - direct[key]) <= TOLERANCE_M, (key, via[key], direct[key])
    a, b = read_run(tmp_path / "adapter"), read_run(tmp_path / "direct")
    np.testing.assert_allclose(a.truth["y"], b.truth["y"], rtol=0, atol=TOLERANCE_M)
    np.testing.assert_allclose(a.mpc_command["delta_front"], b.mpc_command["delta_front"],
                               rtol=0, atol=1e-6)
    # the controllers' input on the adapter path: the sensed state, with estimated tyre data
    assert np.all(a.state["fz"].sum(axis=1) > 0) and np.all(a.state["mu"] == 0.8)
    assert "/vehicle/imu" in a.message_counts and "/vehicle/joint_states" in a.message_counts


def _inputs(k: int, x: float = 1.0, names=JOINT_NAMES):
    stamp = ns_to_stamp(k * 10_000_000)
    odom = Odometry()
    odom.header.stamp = stamp
    odom.pose.pose.position.x, odom.pose.pose.orientation.w = x, 1.0
    odom.twist.twist.linear.x = 16.0
    imu = Imu()
    imu.header.stamp = stamp
    imu.linear_acceleration.y = 1.0
    joints = JointState(name=list(names), position=[0.01] * len(names),
                        velocity=[60.0] * len(names))
    joints.header.stamp = stamp
    return odom, imu, joints


def test_the_adapter_rejects_what_it_cannot_use_and_never_publishes_nan(graph, ros):
    graph([NodeSpec("adapter_node", "fourws_bringup", "adapter_node",
                    params_files=[str(config_dir("fourws_bringup") / "adapter.yaml")])])
    states: dict[int, VehicleState] = {}
    counts: dict[str, int] = {}
    ros.node.create_subscription(VehicleState, "/vehicle/state",
                                 lambda m: states.setdefault(stamp_to_ns(m.header.stamp), m),
                                 CONTROL_QOS)

    def on_diag(msg: DiagnosticArray) -> None:
        for st in msg.status:
            if st.name.endswith("adapter_node"):
                counts.update({kv.key: int(kv.value) for kv in st.values})

    ros.node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, DIAGNOSTICS_QOS)
    pubs = [ros.node.create_publisher(cls, topic, CONTROL_QOS) for cls, topic in (
        (Odometry, "/vehicle/odom"), (Imu, "/vehicle/imu"), (JointState, "/vehicle/joint_states"))]
    assert ros.spin_until(lambda: all(p.get_subscription_count() for p in pubs), 30.0)

    def send(*msgs) -> None:
        for p, m in zip(pubs, msgs, strict=True):
            p.publish(m)

    send(*_inputs(0))
    assert ros.spin_until(lambda: 0 in states, 10.0)
    s = states[0]
    assert (s.x, s.vx, s.ay, s.steer_front) == (1.0, 16.0, 1.0, 0.01)
    assert s.fz.sum() > 7000 and list(s.mu) == [0.8] * 4
    send(*_inputs(1, x=math.nan))                               # not finite
    send(*_inputs(2, names=("steer_front", "wheel_fl")))         # joints missing
    send(*_inputs(3))
    assert ros.spin_until(lambda: 30_000_000 in states, 10.0)
    assert ros.spin_until(lambda: counts.get("bad_input", 0) >= 2, 10.0), counts
    assert 10_000_000 not in states and 20_000_000 not in states
    for m in states.values():
        assert all(math.isfinite(getattr(m, k)) for k in ("x", "y", "yaw", "vx", "vy"))



def _latest_adapter_io(ros):
    """The states the adapter publishes (by stamp), its /diagnostics counts, and publishers
    of odometry, IMU and joint states matched to it."""
    states: dict[int, VehicleState] = {}
    counts: dict[str, int] = {}
    ros.node.create_subscription(VehicleState, "/vehicle/state",
                                 lambda m: states.setdefault(stamp_to_ns(m.header.stamp), m),
                                 CONTROL_QOS)
    ros.node.create_subscription(
        DiagnosticArray, "/diagnostics",
        lambda msg: [counts.update({kv.key: int(kv.value) for kv in st.values})
                     for st in msg.status if st.name.endswith("adapter_node")],
        DIAGNOSTICS_QOS)
    pubs = [ros.node.create_publisher(cls, topic, CONTROL_QOS) for cls, topic in (
        (Odometry, "/vehicle/odom"), (Imu, "/vehicle/imu"), (JointState, "/vehicle/joint_states"))]
    assert ros.spin_until(lambda: all(p.get_subscription_count() for p in pubs), 30.0)
    return states, counts, pubs


def test_latest_sync_rejects_a_stale_imu(graph, ros):
    graph([NodeSpec("adapter_node", "fourws_bringup", "adapter_node",
                    params_files=[str(config_dir("fourws_bringup") / "adapter.yaml")],
                    parameters={"sync": "latest", "max_age_s": 0.05})])
    states, counts, pubs = _latest_adapter_io(ros)
    odom, imu, joints = _inputs(0)
    pubs[1].publish(imu)
    pubs[2].publish(joints)
    assert ros.spin_until(lambda: all(p.wait_for_all_acked(Duration(seconds=0))
                                      for p in pubs[1:]), 10.0)
    pubs[0].publish(odom)                                        # fresh: published
    assert ros.spin_until(lambda: 0 in states, 10.0)
    pubs[0].publish(_inputs(20)[0])                             # 200 ms after the IMU
    assert ros.spin_until(lambda: counts.get("stale_imu", 0) >= 1, 10.0), counts
    assert 200_000_000 not in states, "a state from an IMU 200 ms old"


def test_latest_sync_rejects_an_imu_stamped_ahead_of_the_odometry(graph, ros):
    """An IMU on another clock, stamped ahead of the odometry, had a negative age and was
    reused for every state; beyond max_age_s either way it is refused."""
    graph([NodeSpec("adapter_node", "fourws_bringup", "adapter_node",
                    params_files=[str(config_dir("fourws_bringup") / "adapter.yaml")],
                    parameters={"sync": "latest", "max_age_s": 0.05})])
    states, counts, pubs = _latest_adapter_io(ros)
    pubs[1].publish(_inputs(100)[1])                             # 1 s ahead of the odometry
    pubs[2].publish(_inputs(0)[2])
    assert ros.spin_until(lambda: all(p.wait_for_all_acked(Duration(seconds=0))
                                      for p in pubs[1:]), 10.0)
    pubs[0].publish(_inputs(0)[0])
    assert ros.spin_until(lambda: counts.get("stale_imu", 0) >= 1, 10.0), counts
    assert 0 not in states, "a state from an IMU 1 s ahead of its odometry"
