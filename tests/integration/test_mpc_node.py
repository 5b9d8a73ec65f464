"""mpc_node alone over real topics: stamped answers, NaN states rejected, cached repeats."""

from __future__ import annotations

import math

import numpy as np
import pytest
from rclpy.duration import Duration

from fourws_bringup.supervisor import NodeSpec
from fourws_common.conversions import ns_to_stamp, stamp_to_ns
from fourws_common.qos import CONTROL_QOS, LATCHED_QOS
from fourws_common.resources import config_dir
from fourws_msgs.msg import MpcCommand, MpcDiagnostics, ReferenceTrajectory, VehicleState
from fourws_sim.core.scenario import load_scenario

pytestmark = pytest.mark.integration


def test_mpc_node_answers_states_with_their_stamp_and_rejects_nan(graph, ros):
    preset = config_dir("fourws_bringup") / "controllers" / "improved.yaml"
    graph([NodeSpec("mpc_node", "fourws_mpc", "mpc_node",
                    params_files=[str(config_dir("fourws_mpc") / "mpc.yaml"), str(preset)])])
    cmds: dict[int, list[MpcCommand]] = {}
    diags: dict[int, MpcDiagnostics] = {}
    ros.node.create_subscription(
        MpcCommand, "/control/mpc_command",
        lambda m: cmds.setdefault(stamp_to_ns(m.header.stamp), []).append(m), CONTROL_QOS)
    ros.node.create_subscription(
        MpcDiagnostics, "/control/mpc_diagnostics",
        lambda m: diags.setdefault(stamp_to_ns(m.header.stamp), m), CONTROL_QOS)
    pub_ref = ros.node.create_publisher(ReferenceTrajectory, "/reference/trajectory",
                                        LATCHED_QOS)
    pub = ros.node.create_publisher(VehicleState, "/vehicle/state", CONTROL_QOS)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0
                          and pub_ref.get_subscription_count() > 0)
    path = load_scenario("dlc_60_mu05").path
    pub_ref.publish(ReferenceTrajectory(x=path.x.tolist(), y=path.y.tolist(),
                                        yaw=path.yaw.tolist(),
                                        curvature=path.curvature.tolist(),
                                        speed=path.speed.tolist()))
    ros.spin_until(lambda: False, 1.0)

    def state(k: int, y: float) -> VehicleState:
        m = VehicleState(x=0.1667 * k, y=y, vx=16.667)
        m.header.stamp = ns_to_stamp(k * 10_000_000)
        m.mu = np.full(4, 0.5)
        m.fz = np.full(4, 1800.0)
        return m

    pub.publish(state(0, 0.05))
    assert ros.spin_until(lambda: 0 in cmds and 0 in diags, 10.0)
    pub.publish(state(1, float("nan")))
    pub.publish(state(2, 0.05))
    assert ros.spin_until(lambda: 2 * 10_000_000 in cmds, 10.0)
    assert 10_000_000 not in cmds, "a NaN state was answered"
    pub.publish(state(2, 0.05))  # a repeated stamp is answered from cache, identically
    assert ros.spin_until(lambda: len(cmds[2 * 10_000_000]) >= 2, 10.0)
    first, again = cmds[2 * 10_000_000][:2]
    assert (first.delta_front, first.delta_rear, first.yaw_moment) == \
        (again.delta_front, again.delta_rear, again.yaw_moment)
    for c in (c for v in cmds.values() for c in v):
        assert all(math.isfinite(v) for v in (c.delta_front, c.delta_rear, c.yaw_moment))
    d = diags[0]
    assert d.controller == "improved" and d.np >= 10 and d.solver_status == "optimal"  # DAQP
    assert d.lateral_error == pytest.approx(0.05, abs=0.01)
    # 5 cm left of the path: the controller steers right (negative) to come back.
    assert cmds[0][0].delta_front < 0.0


def test_the_first_state_waits_until_the_outputs_have_their_subscribers(graph, ros):
    """With ``wait_for_subscribers`` (lockstep) the MPC does not answer a run's first state
    until its command and diagnostics publishers have matched that many subscriptions in
    all: a subscriber that joins last (the recorder) still gets step 0. The lockstep plant
    republishes a waiting state; the MPC answers the repeat once the last subscriber is
    matched. (Slowness can only make the silent phase check less, never fail it.)"""
    preset = config_dir("fourws_bringup") / "controllers" / "improved.yaml"
    graph([NodeSpec("mpc_node", "fourws_mpc", "mpc_node",
                    params_files=[str(config_dir("fourws_mpc") / "mpc.yaml"), str(preset)],
                    parameters={"wait_for_subscribers": 3})])
    cmds: dict[int, MpcCommand] = {}
    ros.node.create_subscription(MpcCommand, "/control/mpc_command",
                                 lambda m: cmds.setdefault(stamp_to_ns(m.header.stamp), m),
                                 CONTROL_QOS)
    ros.node.create_subscription(MpcDiagnostics, "/control/mpc_diagnostics", lambda m: None,
                                 CONTROL_QOS)
    pub_ref = ros.node.create_publisher(ReferenceTrajectory, "/reference/trajectory",
                                        LATCHED_QOS)
    pub = ros.node.create_publisher(VehicleState, "/vehicle/state", CONTROL_QOS)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0
                          and pub_ref.get_subscription_count() > 0)
    path = load_scenario("dlc_60_mu05").path
    pub_ref.publish(ReferenceTrajectory(x=path.x.tolist(), y=path.y.tolist(),
                                        yaw=path.yaw.tolist(),
                                        curvature=path.curvature.tolist(),
                                        speed=path.speed.tolist()))
    assert ros.spin_until(lambda: pub_ref.wait_for_all_acked(Duration(seconds=0)), 10.0)
    state = VehicleState(x=0.0, y=0.05, vx=16.667)
    state.mu, state.fz = np.full(4, 0.5), np.full(4, 1800.0)
    for _ in range(4):                          # two of three subscriptions: no answer
        pub.publish(state)
        ros.spin_until(lambda: bool(cmds), 0.25)
    assert not cmds, "answered before every output subscriber was matched"
    late: dict[int, MpcCommand] = {}
    ros.node.create_subscription(MpcCommand, "/control/mpc_command",
                                 lambda m: late.setdefault(stamp_to_ns(m.header.stamp), m),
                                 CONTROL_QOS)

    def answered() -> bool:
        pub.publish(state)                      # the plant's republish of the waiting state
        return ros.spin_until(lambda: 0 in late, 0.25)

    assert ros.spin_until(answered, 20.0), "the third subscriber never got step 0"
    assert 0 in cmds and late[0].delta_front == cmds[0].delta_front


def test_a_state_that_comes_before_the_reference_is_answered_when_it_arrives(graph, ros):
    """/vehicle/state and /reference/trajectory are separate writers: nothing orders them. A
    lockstep bag replay publishes its first state once, so a state that beat the reference
    must be answered when the reference arrives, not dropped (that would stall the replay for
    its lockstep timeout and lose a command)."""
    preset = config_dir("fourws_bringup") / "controllers" / "mpc_4ws.yaml"
    graph([NodeSpec("mpc_node", "fourws_mpc", "mpc_node",
                    params_files=[str(config_dir("fourws_mpc") / "mpc.yaml"), str(preset)])])
    cmds: dict[int, list[MpcCommand]] = {}
    ros.node.create_subscription(
        MpcCommand, "/control/mpc_command",
        lambda m: cmds.setdefault(stamp_to_ns(m.header.stamp), []).append(m), CONTROL_QOS)
    pub_ref = ros.node.create_publisher(ReferenceTrajectory, "/reference/trajectory",
                                        LATCHED_QOS)
    pub = ros.node.create_publisher(VehicleState, "/vehicle/state", CONTROL_QOS)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0
                          and pub_ref.get_subscription_count() > 0)
    state = VehicleState(x=0.0, y=0.05, vx=16.667)
    state.header.stamp = ns_to_stamp(70_000_000)
    state.mu, state.fz = np.full(4, 0.5), np.full(4, 1800.0)
    pub.publish(state)
    assert ros.spin_until(lambda: pub.wait_for_all_acked(Duration(seconds=0)), 10.0)
    ros.spin_until(lambda: bool(cmds), 0.5)
    assert not cmds, "answered a state without a reference"
    path = load_scenario("dlc_60_mu05").path
    pub_ref.publish(ReferenceTrajectory(x=path.x.tolist(), y=path.y.tolist(),
                                        yaw=path.yaw.tolist(),
                                        curvature=path.curvature.tolist(),
                                        speed=path.speed.tolist()))
    assert ros.spin_until(lambda: 70_000_000 in cmds, 10.0), "the waiting state was dropped"
    ros.spin_until(lambda: False, 0.5)
    assert len(cmds[70_000_000]) == 1 and set(cmds) == {70_000_000}
    assert math.isfinite(cmds[70_000_000][0].delta_front)


def test_diagnostics_carry_the_solver_status_and_say_when_the_input_goes_stale(graph, ros):
    """/diagnostics has two statuses per node: the rejection counts (read into metrics.json)
    and ``<node>: runtime``: the last solver status, fallbacks, deadline misses and the
    input's age, OK while states come and WARN once none came for a second."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    from fourws_common.qos import DIAGNOSTICS_QOS

    preset = config_dir("fourws_bringup") / "controllers" / "mpc_4ws.yaml"
    graph([NodeSpec("mpc_node", "fourws_mpc", "mpc_node",
                    params_files=[str(config_dir("fourws_mpc") / "mpc.yaml"), str(preset)])])
    runtime: list[DiagnosticStatus] = []
    ros.node.create_subscription(
        DiagnosticArray, "/diagnostics",
        lambda m: runtime.extend(s for s in m.status if s.name == "/mpc_node: runtime"),
        DIAGNOSTICS_QOS)
    cmds: dict[int, MpcCommand] = {}
    ros.node.create_subscription(MpcCommand, "/control/mpc_command",
                                 lambda m: cmds.setdefault(stamp_to_ns(m.header.stamp), m),
                                 CONTROL_QOS)
    pub_ref = ros.node.create_publisher(ReferenceTrajectory, "/reference/trajectory",
                                        LATCHED_QOS)
    pub = ros.node.create_publisher(VehicleState, "/vehicle/state", CONTROL_QOS)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0
                          and pub_ref.get_subscription_count() > 0)
    path = load_scenario("dlc_60_mu05").path
    pub_ref.publish(ReferenceTrajectory(x=path.x.tolist(), y=path.y.tolist(),
                                        yaw=path.yaw.tolist(),
                                        curvature=path.curvature.tolist(),
                                        speed=path.speed.tolist()))
    assert ros.spin_until(lambda: pub_ref.wait_for_all_acked(Duration(seconds=0)), 10.0)
    state = VehicleState(x=0.0, y=0.02, vx=16.667)
    state.mu, state.fz = np.full(4, 0.5), np.full(4, 1800.0)
    pub.publish(state)
    assert ros.spin_until(lambda: 0 in cmds, 10.0)
    n = len(runtime)
    assert ros.spin_until(lambda: len(runtime) > n, 5.0)
    first = {kv.key: kv.value for kv in runtime[-1].values}
    assert first["solver_status"].startswith("optimal"), first
    assert float(first["input_age_s"]) < 1.0 and runtime[-1].level == DiagnosticStatus.OK
    assert first["fallbacks"] == "0"
    # no state any more: within a few reports the input is stale
    assert ros.spin_until(lambda: runtime[-1].level == DiagnosticStatus.WARN, 10.0)
    assert "no /vehicle/state for" in runtime[-1].message
