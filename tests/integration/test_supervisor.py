"""The graph supervisor over real processes and real DDS (issue: foundation)."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest
from conftest import pid_alive, script_node

from fourws_bringup.supervisor import GraphTimeout, NodeDied, NodeSpec
from fourws_msgs.msg import MpcCommand

pytestmark = pytest.mark.integration


def test_two_nodes_exchange_messages_over_a_real_topic(graph, ros):
    graph([NodeSpec(**script_node("talker.py", "talker")),
           NodeSpec(**script_node("relay.py", "relay"))])
    got: list[MpcCommand] = []
    ros.node.create_subscription(MpcCommand, "relayed_cmd", got.append, 10)
    assert ros.spin_until(lambda: len(got) >= 5, 30.0), "no relayed messages arrived"
    for m in got:
        assert m.delta_front == pytest.approx(2.0 * (m.yaw_moment / 0.5))


def _niceness(pid: int) -> int:
    with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
        return int(fh.read().rsplit(")", 1)[1].split()[16])  # field 19: nice


def test_a_node_spec_nice_lowers_that_process_priority_only(graph):
    sup = graph([NodeSpec(**script_node("talker.py", "talker")),
                 NodeSpec(**script_node("relay.py", "relay"), nice=7)])
    base = os.nice(0)
    assert _niceness(sup.procs["talker"].popen.pid) == base
    assert _niceness(sup.procs["relay"].popen.pid) == min(base + 7, 19)
    with pytest.raises(ValueError, match="nice"):
        NodeSpec("x", "p", "e", nice=-1)


def test_crashing_node_is_reported_by_name_and_the_others_are_stopped(graph):
    sup = graph([NodeSpec(**script_node("talker.py", "talker")),
                 NodeSpec(**script_node("crasher.py", "crasher"))])
    with pytest.raises(NodeDied) as info:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            sup.check()
            time.sleep(0.05)
    assert info.value.name == "crasher"
    assert info.value.returncode == 3
    assert any("simulated fault" in line for line in info.value.last_lines)
    talker_pid = sup.procs["talker"].popen.pid
    sup.stop()
    assert not pid_alive(talker_pid)


def test_a_node_that_sets_done_ends_its_process_with_its_exit_code(graph, ros):
    """run_nodes notices ``done`` on the steady clock (the node runs on sim time, no /clock),
    stops the second node of the process with it and exits with the node's exit code."""
    sup = graph([NodeSpec(**script_node("finisher.py", "finisher"))])
    pub = ros.node.create_publisher(MpcCommand, "finish", 10)
    assert ros.spin_until(lambda: pub.get_subscription_count() >= 1, 20.0)
    pid = sup.procs["finisher"].popen.pid
    with pytest.raises(NodeDied) as info:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            pub.publish(MpcCommand(delta_front=4.0))
            ros.spin_until(lambda: False, 0.05)
            sup.check()
    assert info.value.name == "finisher"
    assert info.value.returncode == 4
    assert not pid_alive(pid)


def test_node_that_never_appears_times_out_naming_it(graph):
    with pytest.raises(GraphTimeout) as info:
        graph([NodeSpec(**script_node("talker.py", "talker")),
               NodeSpec(**script_node("ghost.py", "ghost"))], timeout_s=6.0)
    assert info.value.missing == ["/ghost"]  # fully qualified: graphs in namespaces share a domain
    assert "ghost" in str(info.value)


def test_sigint_to_the_supervisor_leaves_no_process_behind(domain_id, tmp_path):
    """A supervisor process running a graph gets SIGINT: afterwards no node process exists.

    The supervisor process takes SIGINT as a terminal gives it (KeyboardInterrupt), also when
    this suite runs as a background job, which a non-interactive shell starts with SIGINT
    ignored (an ignored signal stays ignored across exec)."""
    here = os.path.dirname(__file__)
    prog = textwrap.dedent(f"""
        import signal, sys, time
        signal.signal(signal.SIGINT, signal.default_int_handler)
        sys.path.insert(0, {here!r})
        from conftest import script_node
        from fourws_bringup.supervisor import NodeSpec, Supervisor
        sup = Supervisor([NodeSpec(**script_node("talker.py", "talker")),
                          NodeSpec(**script_node("relay.py", "relay"))],
                         {domain_id}, {str(tmp_path / "logs")!r})
        try:
            sup.start()
            print("PIDS", *sup.pids(), flush=True)
            while True:
                sup.check()
                time.sleep(0.05)
        except KeyboardInterrupt:
            pass
        finally:
            sup.stop()
            print("STOPPED", flush=True)
    """)
    proc = subprocess.Popen([sys.executable, "-c", prog], stdout=subprocess.PIPE, text=True)
    pids: list[int] = []
    try:
        for line in proc.stdout:
            if line.startswith("PIDS"):
                pids = [int(p) for p in line.split()[1:]]
                break
        assert len(pids) == 2 and all(pid_alive(p) for p in pids)
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=30)
        assert "STOPPED" in out
        assert not [p for p in pids if pid_alive(p)], "node processes survived SIGINT"
    finally:
        _kill_all(proc, pids)


def _kill_all(proc: subprocess.Popen, pids: list[int]) -> None:
    """Leave nothing running after a failed test (no-op when everything has exited)."""
    if proc.poll() is None:
        proc.kill()
        proc.wait()
    for pid in pids:
        if pid_alive(pid):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


def test_killed_supervisor_takes_its_nodes_down(domain_id, tmp_path):
    """Even SIGKILL to the supervisor leaves no node behind (PR_SET_PDEATHSIG)."""
    here = os.path.dirname(__file__)
    prog = textwrap.dedent(f"""
        import sys, time
        sys.path.insert(0, {here!r})
        from conftest import script_node
        from fourws_bringup.supervisor import NodeSpec, Supervisor
        sup = Supervisor([NodeSpec(**script_node("talker.py", "talker"))],
                         {domain_id}, {str(tmp_path / "logs")!r})
        sup.start()
        print("PIDS", *sup.pids(), flush=True)
        time.sleep(60)
    """)
    proc = subprocess.Popen([sys.executable, "-c", prog], stdout=subprocess.PIPE, text=True)
    pids = [int(p) for p in proc.stdout.readline().split()[1:]]
    assert pids and all(pid_alive(p) for p in pids)
    proc.kill()
    proc.wait()
    deadline = time.monotonic() + 10
    while any(pid_alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not [p for p in pids if pid_alive(p)]


def _exits(code: int, after_s: float = 0.0, line: str = "") -> list[str]:
    body = f"import sys, time; time.sleep({after_s}); print({line!r}, flush=True); " \
           f"sys.exit({code})"
    return [sys.executable, "-c", body]


def test_a_normal_end_before_the_graph_saw_it_or_between_polls_is_no_death(graph):
    """The two races of a short run: a process that ends (exit 0, or a run outcome among its
    end_codes) before the start-up probe has seen it in the graph, and one that ends between
    a poll of its own state and ``check()``. Neither is a death; a code outside the end codes
    is, with its last error line."""
    from fourws_common.exit_codes import RUN_END_CODES

    sup = graph([NodeSpec("quick", "", "", argv=_exits(0)),
                 NodeSpec("aborts", "", "", argv=_exits(3), end_codes=RUN_END_CODES),
                 NodeSpec("later", "", "", argv=_exits(0, 0.3))], start=False)
    sup.start(timeout_s=30)  # none of them ever joins the graph: all ended, none died
    sup.procs["later"].popen.wait(timeout=30)
    for _ in range(20):  # the state a poll saw and what check() sees may differ: no matter
        sup.check()
    assert sup.ended() == {"quick": 0, "aborts": 3, "later": 0}
    dead = graph([NodeSpec("dies", "", "", argv=_exits(3, 0.0, "[ERROR] [x]: bad wheel"))],
                 start=False)
    with pytest.raises(NodeDied) as info:
        dead.start(timeout_s=30)
        dead.procs["dies"].popen.wait(timeout=30)
        dead.check()
    assert info.value.returncode == 3 and info.value.last_error == "[ERROR] [x]: bad wheel"
    assert "3 (ABORTED)" in str(info.value)


def test_a_later_stop_stage_takes_every_sample_the_earlier_stage_sent(graph, ros, tmp_path):
    """The recorder's contract at the end of a run: the supervisor stops the writers first
    (stage 0) and each waits for its reliable samples to be acknowledged before it goes
    (``node_main.wait_for_acks``), so the reader of stage 1, stopped after them, has the
    writer's last sample, whatever the loopback lost on the way."""
    sent, taken = tmp_path / "sent.txt", tmp_path / "taken.txt"
    sup = graph([NodeSpec(**script_node("talker.py", "talker"),
                          parameters={"out_file": str(sent)}),
                 NodeSpec(**script_node("tally.py", "tally"), parameters={"out_file": str(taken)},
                          stop_stage=1)])
    got: list[MpcCommand] = []
    ros.node.create_subscription(MpcCommand, "chatter_cmd", got.append, 10)
    assert ros.spin_until(lambda: len(got) >= 10, 30.0), "the talker never talked"
    codes = sup.stop()
    assert codes == {"talker": 0, "tally": 0}
    last_sent = int(sent.read_text())
    assert last_sent >= 10
    assert taken.read_text().strip() == str(last_sent)
