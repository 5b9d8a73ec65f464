"""Run outcomes, new runs, bad input, use_sim_time and parameter changes over real processes.

Each test decides its outcome from records that do not depend on DDS timing — a process's
exit status, the plant's status file, the bag, or messages the test waited for on the graph
— never from a message sent by a process that is exiting.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import cut_scenario
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.duration import Duration

from fourws_bringup import runner
from fourws_bringup.bag.run_data import read_run
from fourws_bringup.core.closed_loop import run_closed_loop
from fourws_bringup.core.configs import load_mpc_config
from fourws_bringup.graph import graph_specs
from fourws_bringup.scoring import score_run
from fourws_bringup.supervisor import NodeDied, NodeSpec
from fourws_common.conversions import fill_vehicle_state, ns_to_stamp, stamp_to_ns
from fourws_common.exit_codes import RUN_END_CODES, ExitCode
from fourws_common.qos import CONTROL_QOS, DIAGNOSTICS_QOS, LATCHED_QOS
from fourws_common.resources import config_dir
from fourws_mpc.core.controller import MpcController, VehicleSample
from fourws_mpc.core.reference import Reference
from fourws_msgs.msg import MpcCommand, ReferenceTrajectory, VehicleState, WheelTorques
from fourws_sim.core.scenario import load_scenario
from fourws_sim.core.simulator import Simulator

pytestmark = pytest.mark.integration
STEP_NS = 10_000_000
CONTROLLER = "improved"


def _cut(tmp_path: Path, end_x_m: float) -> Path:
    return cut_scenario(tmp_path, end_x_m)


@pytest.fixture
def short_scenario(tmp_path) -> Path:
    """dlc_60_mu05 cut at X = 40 m (about 2.4 s): the start of the first lane change."""
    return _cut(tmp_path, 40.0)


def _plant(scenario: Path, status_file: Path, **params) -> NodeSpec:
    return NodeSpec("plant_node", "fourws_sim", "plant_node",
                    params_files=[str(config_dir("fourws_sim") / "plant.yaml")],
                    parameters={"scenario": str(scenario), "status_file": str(status_file),
                                **params}, end_codes=RUN_END_CODES)


def _controllers(mode: str = "lockstep") -> list[NodeSpec]:
    specs = graph_specs("dlc_60_mu05", CONTROLLER, None, mode)
    return [s for s in specs if s.name != "plant_node"]


def _rejections(ros) -> dict[str, dict[str, int]]:
    """Subscribe to /diagnostics; returns the live {node: {kind: count}} of what arrives."""
    seen: dict[str, dict[str, int]] = {}

    def on_diag(msg: DiagnosticArray) -> None:
        for st in msg.status:
            if not st.name.endswith(": runtime"):   # the counts, not the runtime status
                seen[st.name.lstrip("/")] = {kv.key: int(kv.value) for kv in st.values}

    ros.node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, DIAGNOSTICS_QOS)
    return seen


# -- run outcomes ---------------------------------------------------------------------------
class _DeafMonitor:
    """A run monitor that never hears the plant (it matched too late): the outcome must not
    depend on it."""

    def __init__(self, _domain_id: int, _namespace: str = "/") -> None:
        self.sim_time_s, self.wall_time_s, self.status = 0.0, None, {}

    def spin(self, timeout_s: float) -> None:
        time.sleep(timeout_s)

    def close(self) -> None:
        pass


def test_the_outcome_does_not_depend_on_the_monitor_hearing_the_plant(
        short_scenario, tmp_path, monkeypatch):
    monkeypatch.setattr(runner, "_Monitor", _DeafMonitor)
    out = tmp_path / "run"
    started = []           # on_started: once, when the graph is up (fourws run's prefetch)
    outcome = runner.run_graph(str(short_scenario), CONTROLLER, out, progress=False,
                               on_started=lambda: started.append(out.joinpath("logs").is_dir()))
    assert started == [True]
    assert outcome.completed and outcome.exit_code == 0 and outcome.died is None
    assert outcome.reason.startswith("end of scenario") and outcome.steps > 200
    m = score_run(out, outcome)
    assert m["completed"] and m["exit_code"] == 0 and m["reason"] == outcome.reason


def test_plant_exit_codes_name_the_end_of_a_run(graph, short_scenario, tmp_path):
    """No controllers: the plant times out (4); a bad parameter is a start-up error (2)."""
    status = tmp_path / "status.json"
    sup = graph([_plant(short_scenario, status, command_timeout_s=0.5)])
    assert sup.wait_exit("plant_node", timeout_s=60) == ExitCode.TIMEOUT
    st = json.loads(status.read_text())
    assert st["state"] == "ended" and not st["completed"] and st["exit_code"] == 4
    assert "no /control/mpc_command and /control/wheel_torques for step 0" in st["reason"]
    rc, error = _start_fails(graph([_plant(short_scenario, status, dt_s=-1.0)], start=False),
                             "plant_node")
    assert rc == ExitCode.BAD_CONFIG and "dt_s" in error


def _start_fails(sup, name: str) -> tuple[int, str]:
    """Start a node that must fail at start-up; its exit code and last error line. It may
    exit before or after the graph probe has seen it: both are waited for."""
    try:
        sup.start(timeout_s=30)
        rc = sup.wait_exit(name, timeout_s=30)
    except NodeDied as exc:
        rc = exc.returncode
    from fourws_bringup.supervisor import last_error_line

    return rc, last_error_line(sup.procs[name].last_lines())


def test_fourws_run_exits_with_the_runs_outcome(tmp_path):
    """The paper's MPC-FWS as first shipped (eq. (1)-(4): no steering lag, forward Euler, the
    first output scaling; linearly unstable on this plant, ``tests/unit/test_margins.py``)
    leaves the road on dlc_60_mu05: the run ends ABORTED, exit code 3, not a death."""
    preset = yaml.safe_load((config_dir("fourws_bringup") / "controllers" / "mpc_fws.yaml")
                            .read_text(encoding="utf-8"))
    preset["/**/mpc_node"]["ros__parameters"].update(
        controller="paper_mpc_fws", prediction_model="single_track",
        prediction_discretisation="euler", scale_y_m=0.0059, scale_phi_deg=0.30,
        terminal_cost="none")
    path = tmp_path / "paper_mpc_fws.yaml"
    path.write_text(yaml.safe_dump(preset), encoding="utf-8")
    r = subprocess.run(["fourws", "run", "--scenario", "dlc_60_mu05", "--controller",
                        str(path), "--out", str(tmp_path / "r"), "--no-plots",
                        "--compose", "all"], capture_output=True, text=True, timeout=300)
    m = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert r.returncode == ExitCode.ABORTED == m["exit_code"], r.stderr[-2000:]
    assert m["reason"].startswith("aborted") and "died" not in m
    assert m["scenario_file"].endswith("scenarios/dlc_60_mu05.yaml")
    assert len(m["scenario_sha256"]) == 64


def test_unknown_and_mistyped_params_file_keys_are_errors_naming_them(graph, tmp_path):
    for body, name in (({"np_baselin": 30}, "np_baselin"), ({"np_baseline": 12.5},
                                                            "np_baseline")):
        f = tmp_path / f"{name}.yaml"
        f.write_text(yaml.safe_dump({"mpc_node": {"ros__parameters": body}}))
        sup = graph([NodeSpec("mpc_node", "fourws_mpc", "mpc_node",
                              params_files=[str(config_dir("fourws_mpc") / "mpc.yaml"),
                                            str(f)])], start=False)
        rc, error = _start_fails(sup, "mpc_node")
        assert rc == ExitCode.BAD_CONFIG and name in error, error
    # an integer for a float parameter is a float: no error
    f = tmp_path / "int_for_float.yaml"
    f.write_text(yaml.safe_dump({"mpc_node": {"ros__parameters": {"rho": 1000}}}))
    ok = graph([NodeSpec("mpc_node", "fourws_mpc", "mpc_node",
                         params_files=[str(config_dir("fourws_mpc") / "mpc.yaml"), str(f)])])
    # the node is up once its parameter service answers (declared after the check)
    from rclpy.parameter_client import AsyncParameterClient  # noqa: F401  (rclpy API check)

    assert ok.procs["mpc_node"].popen.poll() is None


# -- new runs -------------------------------------------------------------------------------
def _record_states(ros) -> list[VehicleState]:
    got: list[VehicleState] = []
    ros.node.create_subscription(VehicleState, "/vehicle/state", got.append, CONTROL_QOS)
    return got


def _drain(ros, got: list) -> None:
    """Take what the test's readers already hold (the plant waited for their acks)."""
    n = -1
    while n != len(got):
        n = len(got)
        for _ in range(50):
            ros.executor.spin_once(timeout_sec=0.02)


def _trajectory(states: list[VehicleState]) -> np.ndarray:
    first: dict[int, VehicleState] = {}
    for m in states:
        first.setdefault(stamp_to_ns(m.header.stamp), m)
    return np.array([[k, m.x, m.y, m.yaw, m.vx, m.vy, m.yaw_rate, m.steer_front, m.steer_rear,
                      *m.wheel_torque] for k, m in sorted(first.items())])


def test_two_runs_against_the_same_controllers_equal_bit_for_bit(graph, ros, short_scenario,
                                                                 tmp_path):
    ctrl = graph(_controllers())
    states = _record_states(ros)
    runs = []
    for i in range(2):
        status = tmp_path / f"status{i}.json"
        sup = graph([_plant(short_scenario, status, wait_for_subscribers=4,
                            wait_for_reference_subscribers=3)])
        plant = sup.procs["plant_node"].popen
        assert ros.spin_until(lambda p=plant: p.poll() is not None, 120)
        assert plant.returncode == 0
        _drain(ros, states)
        assert json.loads(status.read_text())["completed"]
        # the plant lingers until every reliable subscriber, this test's included, has
        # acknowledged its last state: nothing of this run is still in flight
        runs.append(_trajectory(states))
        states.clear()
    assert runs[0].shape[0] > 200
    assert np.array_equal(runs[0], runs[1])
    ctrl.check()
    mpc_log = (ctrl.log_dir / "mpc_node.log").read_text()
    assert mpc_log.count("new run: controller reset") == 1


# -- bad input ------------------------------------------------------------------------------
@pytest.mark.parametrize("n_strays", [1, 2])
def test_a_future_stamped_state_does_not_freeze_a_running_graph(graph, ros, tmp_path,
                                                                n_strays):
    """One VehicleState stamped 1e6 s ahead, or two back to back 10 ms apart (which confirmed
    each other as a new timeline and froze the run, issue 41 item 2), published into a
    running lockstep graph: every controller rejects them (counted on /diagnostics) and the
    run completes; the bag scores in moments, the strays left out of its timeline."""
    bag = tmp_path / "bag"
    specs = graph_specs("dlc_60_mu05", CONTROLLER, bag, status_file=tmp_path / "s.json")
    specs[0].parameters["wait_for_subscribers"] = 5  # the test's own subscription too
    states = _record_states(ros)
    stray_pub = ros.node.create_publisher(VehicleState, "/vehicle/state", CONTROL_QOS)
    sup = graph(specs)
    assert ros.spin_until(lambda: any(stamp_to_ns(m.header.stamp) >= 50 * STEP_NS
                                      for m in states), 60)
    stray = VehicleState()
    fill_vehicle_state(stray, {k: getattr(states[-1], k) for k in (
        "x", "y", "yaw", "vx", "vy", "yaw_rate", "ax", "ay", "sideslip", "steer_front",
        "steer_rear", "wheel_speed", "wheel_torque", "fx", "fy", "fz", "mu")})
    stray.header.stamp = ns_to_stamp(10**6 * 10**9)
    # every reader of the topic (recorder, controllers, this test: the readers the plant
    # waited for) has matched the stray's writer before it is sent, and has acknowledged it
    # before the run is judged. Counting the readers this node has discovered is not enough:
    # the recorder subscribes to /vehicle/state last (its start gate), and once this node had
    # not yet discovered it, so the stray went to every reader but the recorder.
    readers = specs[0].parameters["wait_for_subscribers"]
    assert ros.spin_until(lambda: readers <= stray_pub.get_subscription_count() and len(
        ros.node.get_subscriptions_info_by_topic("/vehicle/state"))
        <= stray_pub.get_subscription_count(), 30)
    for i in range(n_strays):
        stray.header.stamp = ns_to_stamp(10**6 * 10**9 + i * STEP_NS)
        stray_pub.publish(stray)
    assert stray_pub.wait_for_all_acked(Duration(seconds=10))
    assert sup.wait_exit("plant_node", timeout_s=120) == 0
    sup.stop()
    m = score_run(tmp_path / "bag")
    assert m["completed"] and m["missing_steps"] == 0
    assert m["stray_messages"] == {"/vehicle/state": n_strays}
    # A node took each stray and rejected it, or (keep-last 1, a second writer) the plant's
    # next state or the next stray replaced it in the node's queue before it was taken:
    # either way nothing else was rejected, and the run is the in-process loop's bit for bit.
    for n, counts in m["input_rejections"].items():
        assert set(counts) == {"future_stamp"} and 1 <= counts["future_stamp"] <= n_strays, \
            (n, counts)
    ref = run_closed_loop("dlc_60_mu05", CONTROLLER)
    rec = read_run(tmp_path / "bag")
    assert rec.state["stamp_ns"].max() < 20 * 10**9, "the stray is on the analysis grid"
    n = ref.state["x"].size  # the in-process log has no state after the last step
    assert rec.state["x"].size == n + 1
    for k in ("x", "y", "yaw"):
        assert np.array_equal(rec.state[k][:n], ref.state[k]), k


def _answered(ros, pub, msg: VehicleState, got: dict) -> None:
    """Publish ``msg`` until its stamp is answered, again every 0.25 s as the plant does: the
    first state may reach the node before the reference it needs."""
    stamp = stamp_to_ns(msg.header.stamp)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        pub.publish(msg)
        if ros.spin_until(lambda: stamp in got, 0.25):
            return
    raise AssertionError(f"state {stamp} ns was never answered")


def _ref_msg(scale: float = 1.0) -> ReferenceTrajectory:
    p = load_scenario("dlc_60_mu05").path
    return ReferenceTrajectory(x=(p.x * scale).tolist(), y=(p.y * scale).tolist(),
                               yaw=p.yaw.tolist(), curvature=p.curvature.tolist(),
                               speed=p.speed.tolist())


def _state_msg(k: int, **kw) -> VehicleState:
    m = VehicleState(x=0.1667 * k, y=0.02, vx=16.667)
    m.header.stamp = ns_to_stamp(k * STEP_NS)
    m.mu, m.fz = np.full(4, 0.5), np.full(4, 1800.0)
    for key, v in kw.items():
        setattr(m, key, v)
    return m


@pytest.mark.parametrize(("node", "topic", "bad"), [
    ("speed_pid_node", "/control/drive_command", {"vx": 1.7e308}),
    ("mpc_node", "/control/mpc_command", {"x": 1e300}),
])
def test_a_finite_extreme_is_rejected_and_never_poisons_the_node(graph, ros, node, topic, bad):
    spec = next(s for s in _controllers() if s.name == node)
    sup = graph([spec])
    from fourws_msgs.msg import DriveCommand

    cls = DriveCommand if node == "speed_pid_node" else MpcCommand
    got: dict[int, object] = {}
    ros.node.create_subscription(cls, topic, lambda m: got.setdefault(
        stamp_to_ns(m.header.stamp), m), CONTROL_QOS)
    seen = _rejections(ros)
    pub_ref = ros.node.create_publisher(ReferenceTrajectory, "/reference/trajectory",
                                        LATCHED_QOS)
    pub = ros.node.create_publisher(VehicleState, "/vehicle/state", CONTROL_QOS)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0
                          and pub_ref.get_subscription_count() > 0)
    pub_ref.publish(_ref_msg())
    _answered(ros, pub, _state_msg(0), got)
    for k in range(1, 4):
        pub.publish(_state_msg(k, **(bad if k == 2 else {})))
        if k != 2:
            assert ros.spin_until(lambda k=k: k * STEP_NS in got, 20)
        else:
            assert ros.spin_until(lambda: seen.get(node, {}).get("implausible_state") == 1,
                                  20), seen
    assert 2 * STEP_NS not in got
    values = [v for m in got.values() for v in (
        (m.force, m.torque) if cls is DriveCommand else
        (m.delta_front, m.delta_rear, m.yaw_moment))]
    assert all(math.isfinite(v) for v in values)
    sup.check()


def test_a_poisoned_reference_is_rejected_and_the_node_keeps_answering(graph, ros):
    sup = graph([next(s for s in _controllers() if s.name == "mpc_node")])
    got: dict[int, MpcCommand] = {}
    ros.node.create_subscription(MpcCommand, "/control/mpc_command", lambda m: got.setdefault(
        stamp_to_ns(m.header.stamp), m), CONTROL_QOS)
    seen = _rejections(ros)
    pub_ref = ros.node.create_publisher(ReferenceTrajectory, "/reference/trajectory",
                                        LATCHED_QOS)
    pub = ros.node.create_publisher(VehicleState, "/vehicle/state", CONTROL_QOS)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0
                          and pub_ref.get_subscription_count() > 0)
    pub_ref.publish(_ref_msg())
    _answered(ros, pub, _state_msg(0), got)
    pub_ref.publish(_ref_msg(1e298))
    assert ros.spin_until(lambda: seen.get("mpc_node", {}).get("reference") == 1, 20), seen
    for k in (1, 2):
        pub.publish(_state_msg(k))
        assert ros.spin_until(lambda k=k: k * STEP_NS in got, 20)
        assert math.isfinite(got[k * STEP_NS].delta_front)
    sup.check()


def test_every_node_that_takes_a_reference_refuses_the_same_bad_ones(graph, ros):
    """A reference with two repeated points (the MPC's projection has no direction there) and
    one with a yaw of 1e300 are refused by the MPC, the speed PID and the allocator alike:
    one check for every node (issue 41, item 7)."""
    nodes = ("mpc_node", "speed_pid_node", "allocator_node")
    graph([s for s in _controllers() if s.name in nodes])
    seen = _rejections(ros)
    pub_ref = ros.node.create_publisher(ReferenceTrajectory, "/reference/trajectory",
                                        LATCHED_QOS)
    assert ros.spin_until(lambda: pub_ref.get_subscription_count() >= len(nodes), 30)
    repeated = ReferenceTrajectory(x=[0.0, 0.0], y=[0.0, 0.0], yaw=[0.0, 0.0],
                                   curvature=[0.0, 0.0], speed=[10.0, 10.0])
    huge_yaw = _ref_msg()
    huge_yaw.yaw[5] = 1e300
    for n, msg in enumerate((repeated, huge_yaw), start=1):
        pub_ref.publish(msg)
        assert ros.spin_until(lambda n=n: all(seen.get(node, {}).get("reference") == n
                                              for node in nodes), 20), (n, seen)


# -- use_sim_time ---------------------------------------------------------------------------
def test_use_sim_time_on_every_node_gives_the_same_run(short_scenario, tmp_path):
    plain = runner.run_graph(str(short_scenario), CONTROLLER, tmp_path / "a", progress=False,
                             timeout_s=120)
    sim = runner.run_graph(str(short_scenario), CONTROLLER, tmp_path / "b", progress=False,
                           use_sim_time=True, timeout_s=120)
    assert plain.completed and sim.completed, (plain.reason, sim.reason)
    ra, rb = read_run(tmp_path / "a"), read_run(tmp_path / "b")
    for k in ("x", "y", "yaw", "steer_front", "steer_rear"):
        assert np.array_equal(ra.state[k], rb.state[k]), k
    for log in (tmp_path / "b" / "logs").glob("*.log"):
        text = log.read_text()
        assert "FATAL" not in text and "Traceback" not in text, (log.name, text[-2000:])


# -- parameter changes ----------------------------------------------------------------------
def test_a_parameter_set_mid_run_applies_from_that_step_and_keeps_the_state(graph, ros):
    """The test plays the plant for mpc_node (lockstep, in-process simulator). At step 40 it
    sets q_y_max; at step 80 it loads the node's whole parameter dump back. The commands equal
    bit for bit an in-process controller given the same change at step 40 and nothing else:
    no rebuild, no reset, and a load of its own values changes nothing."""
    from rcl_interfaces.msg import Parameter as ParameterMsg
    from rcl_interfaces.srv import GetParameters, ListParameters, SetParameters
    from rclpy.parameter import Parameter

    graph([next(s for s in _controllers() if s.name == "mpc_node")])
    got: dict[int, MpcCommand] = {}
    ros.node.create_subscription(MpcCommand, "/control/mpc_command", lambda m: got.setdefault(
        stamp_to_ns(m.header.stamp), m), CONTROL_QOS)
    pub_ref = ros.node.create_publisher(ReferenceTrajectory, "/reference/trajectory",
                                        LATCHED_QOS)
    pub = ros.node.create_publisher(VehicleState, "/vehicle/state", CONTROL_QOS)
    set_cli = ros.node.create_client(SetParameters, "/mpc_node/set_parameters")
    list_cli = ros.node.create_client(ListParameters, "/mpc_node/list_parameters")
    get_cli = ros.node.create_client(GetParameters, "/mpc_node/get_parameters")
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0
                          and pub_ref.get_subscription_count() > 0 and set_cli.service_is_ready()
                          and list_cli.service_is_ready() and get_cli.service_is_ready(), 30)

    def call(cli, req):
        fut = cli.call_async(req)
        assert ros.spin_until(fut.done, 30)
        return fut.result()

    scenario = load_scenario("dlc_60_mu05")
    ref_msg = _ref_msg()
    pub_ref.publish(ref_msg)
    cfg = load_mpc_config(CONTROLLER)
    oracle = MpcController(cfg)
    ref = Reference.from_arrays(ref_msg.x, ref_msg.y, ref_msg.yaw, ref_msg.curvature,
                                ref_msg.speed, search_back=cfg.ref_search_back,
                                search_ahead=cfg.ref_search_ahead)
    sim = Simulator.from_scenario(scenario)
    torque = np.full(4, 60.0)
    new_cfg = load_mpc_config(CONTROLLER, {"q_y_max": 4000.0})
    for k in range(120):
        if k == 40:
            req = SetParameters.Request(parameters=[
                Parameter("q_y_max", value=4000.0).to_parameter_msg()])
            assert call(set_cli, req).results[0].successful
            oracle.update_config(new_cfg)
        if k == 80:  # `ros2 param load` of the node's own dump: every value set again
            names = [n for n in call(list_cli, ListParameters.Request()).result.names
                     if n != "start_type_description_service"]  # read-only
            vals = call(get_cli, GetParameters.Request(names=names)).values
            req = SetParameters.Request(parameters=[
                ParameterMsg(name=n, value=v) for n, v in zip(names, vals, strict=True)])
            assert all(r.successful for r in call(set_cli, req).results)
        o = sim.outputs()
        msg = VehicleState()
        fill_vehicle_state(msg, o)
        msg.header.stamp = ns_to_stamp(k * STEP_NS)
        _answered(ros, pub, msg, got)
        c = got[k * STEP_NS]
        r = oracle.step(k * 0.01, VehicleSample.of(msg), ref, mu=float(np.mean(msg.mu)))
        assert (c.delta_front, c.delta_rear, c.yaw_moment) == \
            (r.delta_front, r.delta_rear, r.yaw_moment), k
        sim.step(c.delta_front, c.delta_rear, torque, dt_s=0.01)


# -- realtime -------------------------------------------------------------------------------
def _assert_started_on_the_answer(run) -> None:
    """A realtime plant's step 1 was sent after the answers to step 0 (send times)."""
    assert run.state["stamp_ns"][1] == STEP_NS
    assert run.mpc_command["stamp_ns"][0] == 0 == run.wheel_torques["stamp_ns"][0]
    assert run.state["wall_ns"][1] >= max(run.mpc_command["wall_ns"][0],
                                          run.wheel_torques["wall_ns"][0])


def test_a_realtime_mpc_stall_gives_a_safe_hold_and_no_backlog(graph, ros, tmp_path):
    """SIGSTOP the MPC for 2 s of a realtime run: the plant counts late commands and holds
    safe (steer held, torques 0) after command_hold_timeout_s (0.5 s); resumed, the MPC
    answers the newest state, not the 200 it missed. The bag starts at step 0.

    The stall is timed on the graph, not by sleeps: the plant waits for this test's state
    subscription, made only once every node is up, so the test sees the run from its start;
    the MPC stays stopped until the test has seen the plant step 200 times past the stop."""
    status = tmp_path / "status.json"
    # 100 m, about 6 s: 1 s of run, the 2 s stall, 3 s after it
    specs = graph_specs(str(_cut(tmp_path, 100.0)), CONTROLLER, tmp_path / "bag",
                               mode="realtime", status_file=status)
    specs[0].parameters["wait_for_subscribers"] = 5  # the test's own subscription too
    sup = graph(specs)
    mpc_pid = sup.procs["mpc_node"].popen.pid
    states = _record_states(ros)  # the plant starts on this subscription

    def newest() -> int:  # a reliable stream arrives in order
        return stamp_to_ns(states[-1].header.stamp) // STEP_NS if states else -1

    assert ros.spin_until(lambda: newest() >= 100, 60), "the run did not start"
    os.kill(mpc_pid, signal.SIGSTOP)
    try:
        stopped_at = newest()
        stalled = ros.spin_until(lambda: newest() >= stopped_at + 200, 30)
    finally:
        os.kill(mpc_pid, signal.SIGCONT)
    assert stalled, f"the plant did not step on while the MPC stood (newest {newest()})"
    assert sup.wait_exit("plant_node", timeout_s=60) in RUN_END_CODES
    sup.stop()
    st = json.loads(status.read_text())
    assert st["mode"] == "realtime"
    assert st["late_commands"] >= 100 and st["safe_hold_steps"] >= 50, st
    run = read_run(tmp_path / "bag")
    assert run.state["stamp_ns"][0] == 0, "the recording missed the start"
    _assert_started_on_the_answer(run)
    cmd = np.asarray(run.mpc_command["stamp_ns"])
    n_states = run.state["stamp_ns"].size
    # a backlog worked through would answer every state; the newest-state rule skips most of
    # the ~200 the stall held back
    assert cmd.size <= n_states - 100, (cmd.size, n_states)
    # resumed, the MPC's next answer is to a state about 2 s later than its last before
    assert (np.diff(cmd) // STEP_NS).max() >= 100, "the MPC worked through the backlog"


def test_a_stalled_mpc_takes_the_newest_states_at_once_when_it_resumes(graph, ros):
    """Issue 41, item 5. The MPC (``sync: latest``, as in realtime) is stopped for 2 s. The
    first state it handles when it resumes is one stamped before the stall (the transport
    delivered it so in about half the measured runs; sent here after SIGCONT so that it always
    is); then come the plant's newest states, 2 s ahead. It must take them at the first
    confirmation: one rejected (a lone jump may be a stray), the next answered. Before, the
    old state made the old timeline look alive, so the newest were rejected as strays for 1 s
    (``TIMELINE_QUIET_NS``): the MPC answered 1 s late, the plant held safe 2.5 s, not 1.5 s.
    Its state subscription is best effort: a reliable one delivers nothing past a state lost
    in the stall until the writer re-sends it (with Fast DDS's 3 s heartbeat the MPC answered
    1.8-2.5 s late)."""
    from rclpy.qos import ReliabilityPolicy

    preset = config_dir("fourws_bringup") / "controllers" / "improved.yaml"
    sup = graph([NodeSpec("mpc_node", "fourws_mpc", "mpc_node",
                          params_files=[str(config_dir("fourws_mpc") / "mpc.yaml"), str(preset)],
                          parameters={"sync": "latest"})])
    answered: set[int] = set()
    ros.node.create_subscription(
        MpcCommand, "/control/mpc_command",
        lambda m: answered.add(stamp_to_ns(m.header.stamp) // STEP_NS), CONTROL_QOS)
    rejected = _rejections(ros)
    pub_ref = ros.node.create_publisher(ReferenceTrajectory, "/reference/trajectory",
                                        LATCHED_QOS)
    pub = ros.node.create_publisher(VehicleState, "/vehicle/state", CONTROL_QOS)

    def state_subscriptions() -> list:
        return [i.qos_profile.reliability for i in
                ros.node.get_subscriptions_info_by_topic("/vehicle/state")
                if i.node_name == "mpc_node"]

    assert ros.spin_until(lambda: pub.get_subscription_count() > 0
                          and pub_ref.get_subscription_count() > 0 and state_subscriptions())
    assert state_subscriptions() == [ReliabilityPolicy.BEST_EFFORT]
    path = load_scenario("dlc_60_mu05").path
    pub_ref.publish(ReferenceTrajectory(x=path.x.tolist(), y=path.y.tolist(),
                                        yaw=path.yaw.tolist(), curvature=path.curvature.tolist(),
                                        speed=path.speed.tolist()))

    def answer(k: int) -> bool:
        """Publish the state stamped k until it is answered (a best-effort sample may be lost;
        a repeat is answered from cache)."""
        m = VehicleState(x=0.1667 * k, y=0.05, vx=16.667, mu=[0.5] * 4, fz=[1800.0] * 4)
        m.header.stamp = ns_to_stamp(k * STEP_NS)
        for _ in range(40):
            pub.publish(m)
            if ros.spin_until(lambda: k in answered, 0.5):
                return True
        return False

    def futures() -> int:
        return rejected.get("mpc_node", {}).get("future_stamp", 0)

    assert answer(0), "the MPC never answered"
    mpc_pid = sup.procs["mpc_node"].popen.pid
    os.kill(mpc_pid, signal.SIGSTOP)
    try:
        time.sleep(2.0)  # the stall itself
    finally:
        os.kill(mpc_pid, signal.SIGCONT)
    assert answer(1)  # stamped before the stall
    # the plant's newest states, 2 s ahead, one at a time until one is answered; each is
    # answered or rejected (or lost: the next one follows after 1 s)
    newest = 201
    while newest not in answered:
        assert newest < 251, f"{futures()} newest states rejected, none answered"
        seen = futures()
        m = VehicleState(x=0.1667 * newest, y=0.05, vx=16.667, mu=[0.5] * 4, fz=[1800.0] * 4)
        m.header.stamp = ns_to_stamp(newest * STEP_NS)
        pub.publish(m)
        ros.spin_until(lambda n=newest, s=seen: n in answered or futures() > s, 1.0)
        newest += newest not in answered
    assert ros.spin_until(lambda: futures() >= 1, 5.0)
    assert futures() == 1, f"{futures()} newest states rejected before one was answered"


def test_a_realtime_plant_holds_its_first_state_until_the_controllers_answer(
        graph, ros, short_scenario, tmp_path):
    """Issue 41, item 9: in 1 of 7 realtime launches the plant stepped before the MPC
    answered (2.6 s of safe hold at the start). A realtime plant now waits for the first
    state's answer as lockstep waits for every step's: it republishes state 0 and steps
    only once its MpcCommand and WheelTorques have arrived; with no controller it ends
    with a timeout (exit 4), as lockstep does. fourws run and ros2 launch start this node."""
    status = tmp_path / "alone.json"
    sup = graph([_plant(short_scenario, status, mode="realtime", command_timeout_s=0.5)])
    assert sup.wait_exit("plant_node", timeout_s=60) == ExitCode.TIMEOUT
    st = json.loads(status.read_text())
    assert st["steps"] == 0 and st["exit_code"] == 4, st
    assert "no /control/mpc_command and /control/wheel_torques for step 0" in st["reason"]

    seen: list[int] = []
    ros.node.create_subscription(VehicleState, "/vehicle/state",
                                 lambda m: seen.append(stamp_to_ns(m.header.stamp)), CONTROL_QOS)
    ros.node.create_subscription(ReferenceTrajectory, "/reference/trajectory", lambda m: None,
                                 LATCHED_QOS)
    graph([_plant(short_scenario, tmp_path / "status.json", mode="realtime",
                  wait_for_subscribers=1, wait_for_reference_subscribers=1,
                  republish_period_s=0.05)])
    # a controller slow to come up: nothing answered until state 0 came three times
    assert ros.spin_until(lambda: len(seen) >= 3, 30.0), "the plant never started"
    assert set(seen) == {0}, f"the plant stepped unanswered: stamps {sorted(set(seen))[:5]}"
    pub_cmd = ros.node.create_publisher(MpcCommand, "/control/mpc_command", CONTROL_QOS)
    pub_tq = ros.node.create_publisher(WheelTorques, "/control/wheel_torques", CONTROL_QOS)
    assert ros.spin_until(lambda: pub_cmd.get_subscription_count() > 0
                          and pub_tq.get_subscription_count() > 0)
    pub_cmd.publish(MpcCommand())              # stamped 0: the answer to state 0
    pub_tq.publish(WheelTorques(torque=[0.0] * 4))
    assert ros.spin_until(lambda: max(seen) >= STEP_NS, 20.0), "answered, it did not step"
    assert sorted(seen) == seen, "stamps went back"
