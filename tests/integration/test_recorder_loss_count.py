"""recorder_node's loss count over real topics: every missing step stamp is counted.

The test's node publishes per-step topics with stamps left out on purpose (as a recorder that
fell behind its queues loses them: no DDS message-lost event); the recorder's closing log
line must name each topic with the number of stamps left out.
"""

from __future__ import annotations

import ast
import os
import re
import signal
from pathlib import Path

import pytest
from rclpy.duration import Duration
from rosgraph_msgs.msg import Clock

from fourws_bringup.supervisor import NodeSpec
from fourws_common.conversions import ns_to_stamp
from fourws_common.qos import CLOCK_QOS, CONTROL_QOS
from fourws_msgs.msg import MpcCommand, VehicleState

pytestmark = pytest.mark.integration

DT_NS = 10_000_000


def test_closing_line_counts_every_step_stamp_missing_per_topic(graph, ros, tmp_path: Path):
    sup = graph([NodeSpec(name="recorder_node", package="fourws_bringup",
                          executable="recorder_node",
                          parameters={"output_dir": str(tmp_path / "bag"),
                                      "topics": "[/clock,/vehicle/state,/control/mpc_command]"})])
    n = ros.node
    pubs = (n.create_publisher(Clock, "/clock", CLOCK_QOS),
            n.create_publisher(VehicleState, "/vehicle/state", CONTROL_QOS),
            n.create_publisher(MpcCommand, "/control/mpc_command", CONTROL_QOS))
    clock, state, cmd = pubs
    assert ros.spin_until(lambda: all(p.get_subscription_count() >= 1 for p in pubs), 30.0)
    for k in range(150):
        stamp = ns_to_stamp(k * DT_NS)
        clock.publish(Clock(clock=stamp))
        if not 50 <= k < 100:
            s = VehicleState()
            s.header.stamp = stamp
            state.publish(s)
        if not 60 <= k < 80:
            c = MpcCommand()
            c.header.stamp = stamp
            cmd.publish(c)
    # every message is in the recorder's reader before it is told to stop (its drain then
    # takes them): the outcome never depends on how fast it was scheduled
    for p in pubs:
        assert p.wait_for_all_acked(Duration(seconds=30))
    proc = sup.procs["recorder_node"].popen
    os.killpg(proc.pid, signal.SIGINT)
    assert proc.wait(timeout=20) == 0
    closing = [ln for ln in sup.procs["recorder_node"].last_lines() if "closed" in ln]
    assert closing, sup.procs["recorder_node"].last_lines()
    m = re.search(r"LOST (\{.*\})", closing[-1])
    assert m, closing[-1]
    assert ast.literal_eval(m.group(1)) == {"/control/mpc_command": 20, "/vehicle/state": 50}
