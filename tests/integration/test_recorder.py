"""recorder_node over real topics: stopped cleanly (SIGINT, SIGTERM) and killed (SIGKILL).

The test's own node publishes the graph's messages at 100 Hz; the bag is then read back by
``rosbags`` (independent reader) and by ``fourws_bringup.bag``.
"""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import script_node
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from fourws_bringup.bag.errors import BagError
from fourws_bringup.bag.recovery import recover
from fourws_bringup.bag.run_data import read_run
from fourws_bringup.supervisor import NodeSpec
from fourws_common.conversions import ns_to_stamp
from fourws_common.qos import CLOCK_QOS, CONTROL_QOS, LATCHED_QOS
from fourws_msgs.msg import MpcCommand, ReferenceTrajectory, VehicleState

pytestmark = pytest.mark.integration

DT_NS = 10_000_000


def recorder(out: Path, **params) -> NodeSpec:
    return NodeSpec(name="recorder_node", package="fourws_bringup", executable="recorder_node",
                    parameters={"output_dir": str(out), **params})


def state(k: int) -> VehicleState:
    m = VehicleState()
    m.header.stamp = ns_to_stamp(k * DT_NS)
    m.header.frame_id = "map"
    m.x, m.y, m.yaw, m.vx = 0.167 * k, 0.001 * k, 1e-4 * k, 16.7
    m.wheel_speed = [61.0 + k, 62.0, 63.0, 64.0]
    m.fz = [1800.0, 1801.0, 1802.0, 1803.0 + k]
    return m


class Publisher:
    """The graph's publishers in the test node; ``steps(n)`` publishes n steps at 100 Hz."""

    def __init__(self, ros) -> None:
        n = ros.node
        self.ros = ros
        self.state = n.create_publisher(VehicleState, "/vehicle/state", CONTROL_QOS)
        self.cmd = n.create_publisher(MpcCommand, "/control/mpc_command", CONTROL_QOS)
        self.clock = n.create_publisher(Clock, "/clock", CLOCK_QOS)
        self.ref = n.create_publisher(ReferenceTrajectory, "/reference/trajectory", LATCHED_QOS)
        self.status = n.create_publisher(String, "/run/status", LATCHED_QOS)
        self.ref_msg = ReferenceTrajectory()
        self.ref_msg.header.frame_id = "map"
        self.ref_msg.x = np.linspace(0, 100, 101).tolist()
        self.ref_msg.y = [0.0] * 101
        self.ref_msg.yaw = self.ref_msg.curvature = [0.0] * 101
        self.ref_msg.speed = [16.7] * 101
        self.ref.publish(self.ref_msg)  # latched before the recorder exists: must still arrive
        self.status.publish(String(data=json.dumps({"state": "running", "scenario": "t"})))

    def wait_matched(self) -> None:
        pubs = (self.state, self.cmd, self.clock, self.ref, self.status)
        assert self.ros.spin_until(lambda: all(p.get_subscription_count() >= 1 for p in pubs),
                                   30.0), "the recorder never subscribed"

    def steps(self, n: int, start: int = 0, end_status: bool = True) -> None:
        t0 = time.monotonic() - start * 0.01
        for k in range(start, start + n):
            self.clock.publish(Clock(clock=ns_to_stamp(k * DT_NS)))
            s = state(k)
            self.state.publish(s)
            self.cmd.publish(MpcCommand(header=s.header, delta_front=1e-3 * k,
                                        yaw_moment=5.0 * k))
            delay = t0 + (k + 1) * 0.01 - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        if not end_status:
            return
        self.status.publish(String(data=json.dumps({"state": "ended", "completed": True,
                                                    "scenario": "t", "steps": n})))


def check_complete_bag(folder: Path, n: int) -> None:
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import Reader

    with Reader(folder) as r:
        counts = {c.topic: c.msgcount for c in r.connections}
    assert counts["/vehicle/state"] == n and counts["/control/mpc_command"] == n
    assert counts["/clock"] == n and counts["/reference/trajectory"] == 1
    assert counts["/run/status"] == 2
    got: dict[str, list] = {}
    with AnyReader([folder]) as r:
        for c, _t, raw in r.messages():
            got.setdefault(c.topic, []).append(r.deserialize(raw, c.msgtype))
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in got["/vehicle/state"]]
    assert stamps == [k * DT_NS for k in range(n)], "every state, in order"
    for k, m in enumerate(got["/vehicle/state"]):
        src = state(k)
        assert (m.x, m.y, m.yaw, m.vx) == (src.x, src.y, src.yaw, src.vx)
        np.testing.assert_array_equal(m.wheel_speed, src.wheel_speed)
        np.testing.assert_array_equal(m.fz, src.fz)
    assert [m.yaw_moment for m in got["/control/mpc_command"]] == [5.0 * k for k in range(n)]
    assert [json.loads(m.data)["state"] for m in got["/run/status"]] == ["running", "ended"]
    meta = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["custom_data"]["fourws_state"] == "complete"
    run = read_run(folder)
    assert run.steps == n and run.status["state"] == "ended"
    np.testing.assert_allclose(run.mpc_command["yaw_moment"], 5.0 * np.arange(n))
    np.testing.assert_array_equal(run.reference["x"], np.linspace(0, 100, 101))


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["sigint", "sigterm"])
def test_stopped_recorder_leaves_a_whole_bag_with_every_message(graph, ros, tmp_path, sig):
    out = tmp_path / "run" / "bag"
    sup = graph([recorder(out)])
    pub = Publisher(ros)
    pub.wait_matched()
    n = 250
    pub.steps(n)
    proc = sup.procs["recorder_node"].popen
    os.killpg(proc.pid, sig)
    assert proc.wait(timeout=20) == 0, sup.procs["recorder_node"].last_lines()
    assert any("closed" in line for line in sup.procs["recorder_node"].last_lines())
    check_complete_bag(out, n)


def _durable_count(folder: Path) -> int:
    meta = yaml.safe_load((folder / "metadata.yaml").read_text())
    return int(meta["rosbag2_bagfile_information"]["message_count"])


def wait_durable_count_stable(folder: Path, quiet_s: float = 1.0) -> None:
    """Wait until the recorder has written what it will (its durable count stops changing)."""
    last, stable_since = -1, time.monotonic()
    while time.monotonic() - stable_since < quiet_s:
        c = _durable_count(folder)
        if c != last:
            last, stable_since = c, time.monotonic()
        time.sleep(0.05)


def test_killed_recorder_bag_is_a_clear_error_and_recovers_to_the_last_chunk(graph, ros,
                                                                             tmp_path):
    from rosbags.highlevel import AnyReader

    out = tmp_path / "run" / "bag"
    sup = graph([recorder(out, chunk_size_bytes=4096)])
    pub = Publisher(ros)
    pub.wait_matched()
    n = 300
    pub.steps(n)
    total = 3 * n + 3  # states, commands, clock; reference; two statuses
    wait_durable_count_stable(out)
    if _durable_count(out) == total:
        # The last message happened to close a chunk; one more step (3 small messages, far
        # below a chunk) is then certain to sit in the open chunk when the recorder is killed.
        pub.steps(1, start=n, end_status=False)
        total += 3
        wait_durable_count_stable(out)
    proc = sup.procs["recorder_node"].popen
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)
    mcap = out / "bag_0.mcap"

    meta = yaml.safe_load((out / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["custom_data"]["fourws_state"] == "recording"
    durable = meta["message_count"]
    assert 0 < durable < total

    for p in (tmp_path / "run", out, mcap):
        with pytest.raises(BagError) as info:
            read_run(p)
        assert str(mcap) in str(info.value) and "recover" in str(info.value)

    fixed = tmp_path / "fixed.mcap"
    recovered = recover(mcap, fixed)
    assert recovered == durable
    with AnyReader([fixed]) as r:
        states = [r.deserialize(raw, c.msgtype) for c, _t, raw in r.messages()
                  if c.topic == "/vehicle/state"]
    assert len(states) > 0
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in states]
    assert stamps == [k * DT_NS for k in range(len(states))], "a gap-free prefix of the run"
    assert all(m.x == state(k).x for k, m in enumerate(states))
    run = read_run(fixed)
    assert run.steps == len(states) and run.reference is not None


def test_recorder_refuses_a_non_empty_output_folder_naming_the_parameter(graph, tmp_path):
    from fourws_bringup.supervisor import NodeDied

    out = tmp_path / "bag"
    out.mkdir()
    (out / "old.mcap").write_bytes(b"x")
    with pytest.raises(NodeDied) as info:
        # The node can show in the graph before its constructor rejects the folder: the
        # supervisor's start then returns, and the death is seen by the next check.
        sup = graph([recorder(out)])
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline:
            sup.check()
            time.sleep(0.05)
    assert info.value.returncode == 2
    assert any("output_dir" in line and str(out) in line for line in info.value.last_lines)
    assert (out / "old.mcap").read_bytes() == b"x"


def test_start_gate_subscribes_to_the_state_only_once_the_commands_are_matched(
        graph, ros, tmp_path):
    """With start_gate_topic = /vehicle/state the recorder subscribes to the state (which a
    lockstep plant waits for) only after a /control/mpc_command publisher has matched, so a
    lockstep graph cannot start before the recorder takes the MPC's first command."""
    out = tmp_path / "gated"
    state_pub = ros.node.create_publisher(VehicleState, "/vehicle/state", CONTROL_QOS)
    graph([recorder(out, topics="[/vehicle/state,/control/mpc_command]",
                    start_gate_topic="/vehicle/state", start_gate_timeout_s=60.0)])
    time.sleep(2.0)
    ros.spin_until(lambda: False, 1.0)
    assert state_pub.get_subscription_count() == 0, "subscribed before the command matched"
    cmd_pub = ros.node.create_publisher(MpcCommand, "/control/mpc_command", CONTROL_QOS)
    assert ros.spin_until(lambda: state_pub.get_subscription_count() == 1, 30.0), \
        "the gate never opened"
    assert cmd_pub.get_subscription_count() == 1


def test_a_lockstep_bag_has_simulated_log_times_and_send_times_as_publish_times(tmp_path):
    """``fourws run`` in lockstep records on simulated time (rosbag2's --use-sim-time), so
    ``ros2 bag play`` paces it at the simulated rate: each step's messages are logged at about
    their stamp, never on the wall clock, and the bag lasts as long as the simulated run.
    ``publish_time`` is the publisher's send time and ``sequence`` its sequence number (DDS's
    message info, as rosbag2 writes them): a command is sent after the state it answers, and
    every publisher's numbers rise. metadata.yaml and its copy inside the MCAP carry the same
    custom_data, which says so, and the step latencies are measured on the send times."""
    import subprocess

    from conftest import cut_scenario
    from mcap.reader import make_reader

    out = tmp_path / "run"
    t0 = time.time_ns()
    r = subprocess.run(["fourws", "run", "--scenario", str(cut_scenario(tmp_path, 40.0)),
                        "--controller", "mpc_4ws", "--out", str(out), "--no-plots"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    t1 = time.time_ns()
    rows: dict[str, list[tuple[int, int, int]]] = {}
    seqs: dict[str, list[int]] = {}
    with open(out / "bag" / "bag_0.mcap", "rb") as fh:
        reader = make_reader(fh)
        for _schema, channel, msg in reader.iter_messages(log_time_order=False):
            stamp = int.from_bytes(msg.data[4:8], "little") * 10**9 + int.from_bytes(
                msg.data[8:12], "little")
            rows.setdefault(channel.topic, []).append((msg.log_time, msg.publish_time, stamp))
            seqs.setdefault(channel.topic, []).append(msg.sequence)
        inner = next(m for m in reader.iter_metadata() if m.name == "rosbag2")
    inner = yaml.safe_load(inner.metadata["serialized_metadata"])
    meta = yaml.safe_load((out / "bag" / "metadata.yaml").read_text())
    meta = meta["rosbag2_bagfile_information"]
    assert inner["custom_data"] == meta["custom_data"]
    assert meta["custom_data"]["fourws_log_time"] == "sim_time"
    assert meta["custom_data"]["fourws_publish_time"] == "send_time"
    for topic, seq in seqs.items():
        if topic == "/diagnostics":
            continue  # a publisher per node, each with its own numbers
        assert seq[0] >= 1 and all(b > a for a, b in zip(seq, seq[1:], strict=False)), topic
    sent_state: dict[int, int] = {}  # first send of each step's state (lockstep may repeat)
    for _l, pub, stamp in rows["/vehicle/state"]:
        sent_state[stamp] = min(pub, sent_state.get(stamp, pub))
    commands = rows["/control/mpc_command"]
    assert len(commands) > 200
    for _log, pub, stamp in commands:
        assert pub >= sent_state[stamp], "a command sent before the state it answers"
    states = rows["/vehicle/state"]
    assert len(states) > 200
    lag = np.array([log - stamp for log, _p, stamp in states])
    # simulated time: the recorder's clock is the last /clock it took, about the state's step
    assert np.all(np.abs(lag) < 2 * 10**9) and abs(np.median(lag)) <= 10 * DT_NS, lag
    logs = [log for log, *_r in states]
    assert logs == sorted(logs), "log times went back"
    for _log, pub, _stamp in states:
        assert t0 <= pub <= t1, (pub, t0, t1)                   # wall: during the run
    sim_s = states[-1][2] * 1e-9
    assert abs(meta["duration"]["nanoseconds"] * 1e-9 - sim_s) < 0.05, (meta["duration"], sim_s)
    run = read_run(out)
    assert run.steps == len(states)
    assert run.state["wall_ns"].tolist() == [p for _l, p, _s in states]
    m = json.loads((out / "metrics.json").read_text())
    # step latencies on the wall times (on the simulated log times every step is 10 ms)
    wall_step_ms = np.diff(run.state["wall_ns"]) * 1e-6
    assert m["step_latency_ms"]["step"]["p50"] == pytest.approx(float(np.median(wall_step_ms)))


def test_a_recorder_stopped_with_its_writers_keeps_every_sample_they_sent(graph, ros, tmp_path):
    """``ros2 launch`` signals every process at once: the writer waits for its samples to be
    acknowledged before it leaves (node_main), and the recorder drains until no writer is left
    on a per-step topic, so the bag ends with the writer's last sample."""
    from rosbags.highlevel import AnyReader

    out, sent = tmp_path / "bag", tmp_path / "sent.txt"
    sup = graph([NodeSpec(**script_node("talker.py", "talker"),
                          parameters={"out_file": str(sent)}),
                 recorder(out, topics=["/chatter_cmd:fourws_msgs/msg/MpcCommand"])])
    got: list[MpcCommand] = []
    ros.node.create_subscription(MpcCommand, "/chatter_cmd", got.append, 10)
    assert ros.spin_until(lambda: len(got) >= 10, 30.0), "the talker never talked"
    codes = sup.stop()                                   # one stage: both get SIGINT at once
    assert codes == {"talker": 0, "recorder_node": 0}, sup.procs["recorder_node"].last_lines()
    assert not any("stopped draining" in line for line in sup.procs["recorder_node"].last_lines())
    with AnyReader([out]) as r:
        counts = [int(r.deserialize(raw, c.msgtype).delta_front) for c, _t, raw in r.messages()]
    assert counts and max(counts) == int(sent.read_text())
