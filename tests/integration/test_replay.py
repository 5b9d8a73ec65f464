"""replay_node over real topics: a bag written here is published again, with /clock, paced,
and in lockstep with a controller (the test node) answering each state."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from fourws_bringup.bag.writer import BagWriter
from fourws_bringup.supervisor import NodeSpec
from fourws_common.conversions import ns_to_stamp, stamp_to_ns
from fourws_common.qos import CLOCK_QOS, CONTROL_QOS, LATCHED_QOS
from fourws_common.topics import topic_info
from fourws_msgs.msg import MpcCommand, ReferenceTrajectory, VehicleState

pytestmark = pytest.mark.integration

DT_NS = 10_000_000


#: how late the replay's first send may be against its own start (one tick), s
TOLERANCE_S = 0.15


def state(k: int) -> VehicleState:
    m = VehicleState()
    m.header.stamp = ns_to_stamp(k * DT_NS)
    m.header.frame_id = "map"
    m.x, m.y, m.vx, m.yaw_rate = 0.167 * k, -0.002 * k, 16.7, 0.01 * k
    m.wheel_torque = [1.0 * k, 2.0, 3.0, 4.0]
    return m


def command(k: int) -> MpcCommand:
    return MpcCommand(header=state(k).header, delta_front=1e-3 * k, delta_rear=-1e-3 * k,
                      yaw_moment=7.0 * k)


def reference() -> ReferenceTrajectory:
    m = ReferenceTrajectory()
    m.header.frame_id = "map"
    m.x = [0.0, 1.0, 2.0]
    m.y = m.yaw = m.curvature = [0.0, 0.0, 0.0]
    m.speed = [16.7] * 3
    return m


def write_bag(folder: Path, n: int, repeat_every: int = 0) -> None:
    """A bag as a lockstep run leaves it (clock, state, command per step; latched reference and
    status); ``repeat_every`` adds the plant's republished states."""
    names = ["/clock", "/vehicle/state", "/control/mpc_command", "/reference/trajectory",
             "/run/status"]
    w = BagWriter(folder, [topic_info(t) for t in names], chunk_size_bytes=8192)
    t = 1_700_000_000_000_000_000
    w.write("/reference/trajectory", serialize_message(reference()), t)
    w.write("/run/status", serialize_message(String(data=json.dumps({"state": "running"}))), t)
    for k in range(n):
        t += 1_000_000
        w.write("/clock", serialize_message(Clock(clock=ns_to_stamp(k * DT_NS))), t)
        w.write("/vehicle/state", serialize_message(state(k)), t + 1)
        if repeat_every and k % repeat_every == 1:
            w.write("/vehicle/state", serialize_message(state(k)), t + 2)
        w.write("/control/mpc_command", serialize_message(command(k)), t + 3)
    w.close()


def replay(bag: Path, **params) -> NodeSpec:
    return NodeSpec(name="replay_node", package="fourws_bringup", executable="replay_node",
                    parameters={"bag": str(bag), "wait_for_subscribers": True,
                                "start_delay_s": 0.3, **params})


class Listener:
    def __init__(self, ros, topics=("/vehicle/state", "/control/mpc_command",
                                    "/reference/trajectory", "/clock")) -> None:
        self.states: list[tuple[float, VehicleState]] = []
        self.sent_s: list[float] = []  # each state's send time (DDS source timestamp), s
        self.cmds: list[MpcCommand] = []
        self.refs: list[ReferenceTrajectory] = []
        self.clock: list[int] = []
        n = ros.node
        if "/vehicle/state" in topics:
            n.create_subscription(VehicleState, "/vehicle/state", self._on_state, CONTROL_QOS)
        if "/control/mpc_command" in topics:
            n.create_subscription(MpcCommand, "/control/mpc_command", self.cmds.append,
                                  CONTROL_QOS)
        if "/reference/trajectory" in topics:
            n.create_subscription(ReferenceTrajectory, "/reference/trajectory", self.refs.append,
                                  LATCHED_QOS)
        if "/clock" in topics:
            n.create_subscription(Clock, "/clock",
                                  lambda m: self.clock.append(stamp_to_ns(m.clock)), CLOCK_QOS)

    def _on_state(self, msg: VehicleState, info) -> None:
        self.states.append((time.monotonic(), msg))
        self.sent_s.append(info["source_timestamp"] * 1e-9)


def wait_done(sup, ros, timeout_s: float = 40.0) -> None:
    proc = sup.procs["replay_node"].popen
    assert ros.spin_until(lambda: proc.poll() is not None, timeout_s), "replay did not end"
    ros.spin_until(lambda: False, 0.3)  # take what is still queued here
    assert proc.returncode == 0, sup.procs["replay_node"].last_lines()


def test_replay_publishes_every_recorded_message_with_equal_content_and_clock(graph, ros,
                                                                              tmp_path):
    n = 200
    write_bag(tmp_path / "bag", n, repeat_every=10)
    lis = Listener(ros)
    sup = graph([replay(tmp_path / "bag", rate=2.0)])
    wait_done(sup, ros)
    expected_states = [state(k) for k in range(n) for _ in range(2 if k % 10 == 1 else 1)]
    assert [m for _, m in lis.states] == expected_states, "recorded order, repeats included"
    assert lis.cmds == [command(k) for k in range(n)]
    assert lis.refs == [reference()]
    assert lis.clock == [k * DT_NS for k in range(n)], "/clock from the header stamps"
    lines = sup.procs["replay_node"].last_lines()
    assert any(f"replayed {len(expected_states) + n + 1} messages" in x for x in lines), lines


def test_replay_paces_by_simulated_time_and_replays_only_the_chosen_topics(graph, ros,
                                                                           tmp_path):
    n = 100  # 0.99 s of simulated time
    write_bag(tmp_path / "bag", n)
    lis = Listener(ros)
    sup = graph([replay(tmp_path / "bag", rate=2.0, topics="[/vehicle/state]")])
    wait_done(sup, ros)
    assert [m for _, m in lis.states] == [state(k) for k in range(n)]
    assert lis.cmds == [] and lis.refs == []
    # Paced by the sender's clock (the DDS source timestamps: a receiver's callback times
    # bunch when its executor is late). The node sends state k no earlier than t0 + s_k / rate
    # (s_k its simulated time since the first state) and the first at t0; when it falls behind
    # it catches up, so a state may be sent late but never early. (Measuring the span from a
    # state the sender sent late, after a stall, made 0.495 s look like 0.395 s on a busy
    # machine.) Only the first send's own lateness against t0 (within one tick) is unknown:
    # TOLERANCE_S bounds it, far below what a node that ignored the rate would miss by (as
    # fast as possible: milliseconds; rate 4: 0.25 s of the 0.495).
    sent0 = lis.sent_s[0]
    sim0 = stamp_to_ns(lis.states[0][1].header.stamp)
    due = [(stamp_to_ns(m.header.stamp) - sim0) * 1e-9 / 2.0 for _, m in lis.states]
    early = [(k, round(s - sent0, 3), round(d, 3))
             for k, (s, d) in enumerate(zip(lis.sent_s, due, strict=True))
             if s - sent0 < d - TOLERANCE_S]
    assert not early, f"sent before due at rate 2 (k, sent s, due s): {early[:5]}"
    assert due[-1] == pytest.approx((n - 1) * 0.01 / 2.0)


def test_wall_stamped_diagnostics_and_a_stray_neither_pace_nor_clock_the_replay(graph, ros,
                                                                             tmp_path):
    """Issue 41, item 1: /diagnostics carries the nodes' wall-clock stamps (1.8e9 s) among the
    simulated ones, and a stray state sits 1e6 s ahead. Replayed at rate 1, the bag of 1 s
    ends in about 1 s (paced by the simulated stamps it had waited decades for), /clock
    never jumps to a wall or stray value and is published once per simulated step."""
    from diagnostic_msgs.msg import DiagnosticArray

    n = 100
    folder = tmp_path / "bag"
    names = ["/vehicle/state", "/control/mpc_command", "/diagnostics"]
    w = BagWriter(folder, [topic_info(t) for t in names], chunk_size_bytes=8192)
    wall = 1_800_000_000 * 10**9
    for k in range(n):
        t = k * DT_NS
        w.write("/vehicle/state", serialize_message(state(k)), t)
        w.write("/control/mpc_command", serialize_message(command(k)), t + 1)
        if k % 10 == 5:
            diag = DiagnosticArray()
            diag.header.stamp = ns_to_stamp(wall + t)
            w.write("/diagnostics", serialize_message(diag), t + 2)
        if k == 50:
            w.write("/vehicle/state", serialize_message(state(10**8)), t + 3)   # 1e6 s ahead
    w.close()
    lis = Listener(ros, topics=("/vehicle/state", "/clock"))
    t0 = time.monotonic()
    sup = graph([replay(folder, rate=1.0)])
    wait_done(sup, ros, timeout_s=30.0)
    assert time.monotonic() - t0 < 20.0
    assert lis.clock == [k * DT_NS for k in range(n)], lis.clock[:5]
    assert len(lis.states) == n + 1                      # the stray is replayed, as recorded


def test_lockstep_replay_waits_for_the_controller_answer_of_each_state(graph, ros, tmp_path):
    n = 30
    slow_k = 5
    write_bag(tmp_path / "bag", n, repeat_every=10)
    pub = ros.node.create_publisher(MpcCommand, "/control/mpc_command", CONTROL_QOS)
    answered_at: dict[int, float] = {}
    arrivals: list[tuple[int, float]] = []
    pending: list[tuple[float, int]] = []

    def on_state(msg: VehicleState) -> None:
        k = stamp_to_ns(msg.header.stamp) // DT_NS
        arrivals.append((k, time.monotonic()))
        if k in answered_at or any(p[1] == k for p in pending):
            return
        pending.append((time.monotonic() + (1.0 if k == slow_k else 0.0), k))

    def answer() -> None:
        now = time.monotonic()
        for due, k in list(pending):
            if now >= due:
                pending.remove((due, k))
                answered_at[k] = time.monotonic()
                pub.publish(command(k))

    ros.node.create_subscription(VehicleState, "/vehicle/state", on_state, CONTROL_QOS)
    ros.node.create_timer(0.002, answer)
    sup = graph([replay(tmp_path / "bag", rate=0.0, topics="[/vehicle/state]",
                        lockstep_topic="/control/mpc_command", lockstep_timeout_s=20.0)])
    wait_done(sup, ros)
    ks = [k for k, _ in arrivals]
    assert ks == [k for k in range(n) for _ in range(2 if k % 10 == 1 else 1)]
    first_arrival = {}
    for k, t in arrivals:
        first_arrival.setdefault(k, t)
    for k in range(1, n):
        assert first_arrival[k] > answered_at[k - 1], f"state {k} came before answer {k - 1}"
    assert first_arrival[slow_k + 1] - first_arrival[slow_k] >= 0.9
    assert any("0 lockstep answers missed" in x for x in sup.procs["replay_node"].last_lines())


def test_fourws_replay_as_fast_as_possible_ends_normally(domain_id):
    """`fourws replay --rate 0` can end before the start-up probe has seen its node in the
    graph: that is a normal end (exit 0), not a death, on every try."""
    import subprocess

    bag = Path(__file__).resolve().parents[2] / "bags" / "improved@dlc_60_mu05"
    for _ in range(3):
        r = subprocess.run(["fourws", "replay", str(bag), "--rate", "0", "--domain-id",
                            str(domain_id)], capture_output=True, text=True, timeout=300)
        assert r.returncode == 0 and "died" not in r.stderr, r.stderr[-2000:]


def test_a_runtime_parameter_set_is_refused_not_silently_ignored(graph, ros, tmp_path):
    """A replay reads its parameters at start; ``ros2 param set /replay_node rate 5`` was
    answered successful and changed nothing."""
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter

    write_bag(tmp_path / "bag", 200)
    sup = graph([replay(tmp_path / "bag", rate=0.5)])
    cli = ros.node.create_client(SetParameters, "/replay_node/set_parameters")
    assert ros.spin_until(cli.service_is_ready, 30.0)
    fut = cli.call_async(SetParameters.Request(
        parameters=[Parameter("rate", value=5.0).to_parameter_msg()]))
    assert ros.spin_until(fut.done, 30.0)
    res = fut.result().results[0]
    assert not res.successful and "read at start" in res.reason, res
    wait_done(sup, ros)
