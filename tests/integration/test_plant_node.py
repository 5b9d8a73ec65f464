"""plant_node alone over real topics, driven by the test answering each state (plant issue)."""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import String

from fourws_bringup.supervisor import NodeSpec
from fourws_common.conversions import stamp_to_ns
from fourws_common.qos import CONTROL_QOS, DIAGNOSTICS_QOS, LATCHED_QOS
from fourws_common.resources import config_dir
from fourws_msgs.msg import MpcCommand, ReferenceTrajectory, VehicleState, WheelTorques

pytestmark = pytest.mark.integration

SCENARIO = {
    "name": "plant_node_test", "description": "1 s straight start of a 36 km/h lane change",
    "speed_kmh": 36.0, "road": {"type": "constant", "mu": 0.8},
    "path": {"type": "tanh_dlc", "stretch": "auto"}, "duration_s": 1.0,
}


@pytest.fixture
def scenario_file(tmp_path):
    p = tmp_path / "plant_node_test.yaml"
    p.write_text(yaml.safe_dump(SCENARIO))
    return p


def test_plant_completes_a_scenario_answered_over_topics_and_rejects_nan(graph, ros,
                                                                         scenario_file):
    t_launch = time.monotonic()
    graph([NodeSpec("plant_node", "fourws_sim", "plant_node",
                    params_files=[str(config_dir("fourws_sim") / "plant.yaml")],
                    parameters={"scenario": str(scenario_file), "wait_for_subscribers": 1,
                                "status_period_s": 0.05, "republish_period_s": 0.1})])
    states: dict[int, VehicleState] = {}
    status: list[dict] = []
    refs: list[ReferenceTrajectory] = []
    pub_cmd = ros.node.create_publisher(MpcCommand, "/control/mpc_command", CONTROL_QOS)
    pub_tq = ros.node.create_publisher(WheelTorques, "/control/wheel_torques", CONTROL_QOS)
    nan_step = 20
    huge_steer_step, huge_torque_step = 30, 40        # finite but non-physical: 1e300
    first_seen: list[float] = []  # state 0 goes unanswered three times: start-up

    def on_state(msg: VehicleState) -> None:
        k = stamp_to_ns(msg.header.stamp) // 10_000_000
        states.setdefault(k, msg)
        if k == 0:
            first_seen.append(time.monotonic())
            if len(first_seen) <= 3:
                return
        cmd = MpcCommand(delta_front=float("nan") if k == nan_step else
                         1e300 if k == huge_steer_step else 0.0)
        tq = WheelTorques(torque=np.full(4, 1e300 if k == huge_torque_step else 20.0))
        cmd.header = tq.header = msg.header
        pub_cmd.publish(cmd)
        pub_tq.publish(tq)

    ros.node.create_subscription(VehicleState, "/vehicle/state", on_state, CONTROL_QOS)
    ros.node.create_subscription(String, "/run/status",
                                 lambda m: status.append(json.loads(m.data)), LATCHED_QOS)
    ros.node.create_subscription(ReferenceTrajectory, "/reference/trajectory", refs.append,
                                 LATCHED_QOS)
    counts: dict[str, int] = {}          # the plant's rejections, as /diagnostics says them
    ros.node.create_subscription(
        DiagnosticArray, "/diagnostics",
        lambda msg: [counts.update({kv.key: int(kv.value) for kv in st.values
                                    if kv.value.isdigit()})
                     for st in msg.status if st.name.endswith("plant_node")],
        DIAGNOSTICS_QOS)
    assert ros.spin_until(lambda: status and status[-1]["state"] == "ended", 60.0), \
        f"run did not end; got {len(states)} states"
    # the final state and the final status travel on two topics with no order between them:
    # the plant lingers until the state is acknowledged, so wait for it too
    assert ros.spin_until(lambda: 100 in states, 30.0), \
        f"the final state (step 100) never arrived; got steps {sorted(states)[-3:]}"
    end = status[-1]
    assert end["completed"], end
    assert end["steps"] == 100 and end["rejected_commands"] >= 3
    assert ros.spin_until(lambda: counts.get("rejected_command", 0) >= 3, 10.0), counts
    # heartbeats while running: progress in steps, simulated and wall time (the runner's
    # progress line and nothing else per step)
    # start-up (state 0 until its fourth publication) is reported apart and left out of the
    # wall time
    assert len(first_seen) == 4
    # the plant's wait runs from its first publication of state 0 (after the launch, and no
    # later than this test first saw one: earlier copies may reach no subscriber yet) to its
    # publication of the copy that was answered (seen here at first_seen[3], less one
    # delivery latency); CLOCK_MONOTONIC is one clock for every process here
    assert first_seen[3] - first_seen[0] - 0.05 <= end["startup_wait_s"] \
        <= first_seen[3] - t_launch, (end["startup_wait_s"], first_seen, t_launch)
    beats = [s for s in status if s["state"] == "running" and s["steps"] > 0]
    if end["wall_time_s"] > 0.15:
        assert beats, status
    for a, b in zip(beats, beats[1:] + [end], strict=True):
        assert a["steps"] <= b["steps"] and a["wall_time_s"] <= b["wall_time_s"]
        assert a["sim_time_s"] == pytest.approx(a["steps"] * 0.01)
    assert sorted(states) == list(range(101)), "every step 0..100 published once at least"
    for msg in states.values():
        vals = [getattr(msg, k) for k in ("x", "y", "yaw", "vx", "vy", "yaw_rate", "ay")]
        assert all(math.isfinite(v) for v in vals)
        assert np.all(np.isfinite(msg.fz)) and np.all(np.isfinite(msg.fx))
    # The NaN and the 1e300 steer were rejected: the front wheels stayed straight; the 1e300
    # torques too: the car kept the 20 N·m acceleration (clipped to the motors' limit they
    # would have added about 0.06 m/s in one step)
    assert max(abs(m.steer_front) for m in states.values()) < 1e-9
    dv = np.diff([states[k].vx for k in range(101)])
    assert np.max(np.abs(dv)) < 0.02, dv
    assert states[0].vx == pytest.approx(10.0, abs=1e-6) and states[100].x > 9.0
    assert refs and len(refs[0].x) == len(refs[0].speed) > 100


def test_a_runtime_scenario_or_timing_change_is_refused_naming_it(graph, ros):
    """``ros2 param set /plant_node scenario nope`` answers unsuccessful with the reason, and
    the plant keeps its scenario. What the run is built from is fixed at start (one run per
    plant process): another scenario, dt_s or mode is refused too, the same value accepted,
    and an abort limit applies."""
    from rcl_interfaces.srv import GetParameters, SetParameters
    from rclpy.parameter import Parameter

    graph([NodeSpec("plant_node", "fourws_sim", "plant_node",
                    params_files=[str(config_dir("fourws_sim") / "plant.yaml")],
                    parameters={"scenario": "dlc_60_mu05", "wait_for_subscribers": 1})])
    set_cli = ros.node.create_client(SetParameters, "/plant_node/set_parameters")
    get_cli = ros.node.create_client(GetParameters, "/plant_node/get_parameters")
    assert ros.spin_until(lambda: set_cli.service_is_ready() and get_cli.service_is_ready(), 30)

    def call(cli, req):
        fut = cli.call_async(req)
        assert ros.spin_until(fut.done, 30)
        return fut.result()

    def set_scenario(value: str):
        req = SetParameters.Request(parameters=[Parameter("scenario", value=value)
                                                .to_parameter_msg()])
        return call(set_cli, req).results[0]

    def scenario() -> str:
        return call(get_cli, GetParameters.Request(names=["scenario"])).values[0].string_value

    bad = set_scenario("nope")
    assert not bad.successful and "nope" in bad.reason, bad
    assert scenario() == "dlc_60_mu05"
    other = set_scenario("dlc_90_mu06")
    assert not other.successful and "fixed at start" in other.reason, other
    assert scenario() == "dlc_60_mu05"
    assert set_scenario("dlc_60_mu05").successful          # a dump loaded back: no change
    for name, value in (("dt_s", 0.02), ("mode", "realtime")):
        req = SetParameters.Request(parameters=[Parameter(name, value=value)
                                                .to_parameter_msg()])
        res = call(set_cli, req).results[0]
        assert not res.successful and name in res.reason, (name, res)
    req = SetParameters.Request(parameters=[Parameter("abort_sideslip_deg", value=25.0)
                                            .to_parameter_msg()])
    assert call(set_cli, req).results[0].successful
