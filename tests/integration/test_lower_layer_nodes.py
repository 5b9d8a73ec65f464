"""speed_pid_node and allocator_node alone, fed by the test over real topics (lower layer).

The test publishes stamped inputs, checks the answers carry the same stamp and the numbers the
pure cores give for the same inputs (the oracle), and that NaN inputs never produce a
non-finite output.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fourws_bringup.core.configs import core_values
from fourws_bringup.supervisor import NodeSpec
from fourws_common.conversions import ns_to_stamp, stamp_to_ns
from fourws_common.params import from_mapping, load_ros_params_yaml
from fourws_common.qos import CONTROL_QOS, LATCHED_QOS
from fourws_common.resources import config_dir
from fourws_msgs.msg import (
    DriveCommand,
    MpcCommand,
    ReferenceTrajectory,
    VehicleState,
    WheelTorques,
)
from fourws_torque_alloc.core.allocation import AllocatorConfig, allocate
from fourws_torque_alloc.core.pid import SpeedPid, SpeedPidConfig

pytestmark = pytest.mark.integration


def load_pid_yaml(path: str, node: str) -> dict:
    """speed_pid.yaml without the node-level input keys (``configs.core_values``)."""
    return core_values(load_ros_params_yaml(path, node))
CFG = config_dir("fourws_torque_alloc")


def _state(k: int, vx: float, fz, fy, mu) -> VehicleState:
    m = VehicleState()
    m.header.stamp = ns_to_stamp(k * 10_000_000)
    m.x, m.vx = 0.1 * k, vx
    m.wheel_speed = np.full(4, vx / 0.27)          # rolling: the slip limiter stays out
    m.fz, m.fy, m.mu = (np.asarray(a, dtype=float) for a in (fz, fy, mu))
    return m


def test_speed_pid_node_answers_each_state_with_its_stamp_and_the_core_value(graph, ros):
    graph([NodeSpec("speed_pid_node", "fourws_torque_alloc", "speed_pid_node",
                    params_files=[str(CFG / "speed_pid.yaml")])])
    got: dict[int, DriveCommand] = {}
    ros.node.create_subscription(DriveCommand, "/control/drive_command",
                                 lambda m: got.setdefault(stamp_to_ns(m.header.stamp), m),
                                 CONTROL_QOS)
    pub_ref = ros.node.create_publisher(ReferenceTrajectory, "/reference/trajectory",
                                        LATCHED_QOS)
    pub = ros.node.create_publisher(VehicleState, "/vehicle/state", CONTROL_QOS)
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0
                          and pub_ref.get_subscription_count() > 0)
    x = np.linspace(-10.0, 200.0, 2101)
    ref = ReferenceTrajectory(x=x.tolist(), y=[0.0] * x.size, yaw=[0.0] * x.size,
                              curvature=[0.0] * x.size, speed=[16.0] * x.size)
    pub_ref.publish(ref)
    ros.spin_until(lambda: False, 1.0)

    oracle = SpeedPid(from_mapping(SpeedPidConfig,
                                   load_pid_yaml(str(CFG / "speed_pid.yaml"),
                                                        "speed_pid_node")))
    speeds = [15.0, 15.2, 15.5, 15.9, 16.1]
    fz, fy, mu = [2000.0] * 4, [0.0] * 4, [0.8] * 4
    for k, v in enumerate(speeds):
        pub.publish(_state(k, v, fz, fy, mu))
        assert ros.spin_until(lambda k=k: k * 10_000_000 in got, 10.0), f"no answer to {k}"
        want = oracle.step(16.0, v, 0.01)
        cmd = got[k * 10_000_000]
        assert cmd.force == pytest.approx(want.force_n, rel=1e-12, abs=1e-9)
        assert cmd.torque == pytest.approx(want.torque_nm, rel=1e-12, abs=1e-9)

    bad = _state(len(speeds), float("nan"), fz, fy, mu)
    pub.publish(bad)
    pub.publish(_state(len(speeds) + 1, 16.0, fz, fy, mu))
    assert ros.spin_until(lambda: (len(speeds) + 1) * 10_000_000 in got, 10.0)
    assert len(speeds) * 10_000_000 not in got, "a NaN state was answered"
    assert all(math.isfinite(c.force) and math.isfinite(c.torque) for c in got.values())



def _allocator_io(ros):
    """The allocator's answers by stamp, and publishers of its three inputs (s, d, m)
    matched to it."""
    got: dict[int, WheelTorques] = {}
    ros.node.create_subscription(WheelTorques, "/control/wheel_torques",
                                 lambda m: got.setdefault(stamp_to_ns(m.header.stamp), m),
                                 CONTROL_QOS)
    pubs = {t: ros.node.create_publisher(c, n, CONTROL_QOS) for t, c, n in (
        ("s", VehicleState, "/vehicle/state"), ("d", DriveCommand, "/control/drive_command"),
        ("m", MpcCommand, "/control/mpc_command"))}
    assert ros.spin_until(lambda: all(p.get_subscription_count() > 0 for p in pubs.values()))
    return got, pubs


@pytest.mark.parametrize("method", ["optimal", "rule"])
def test_allocator_node_combines_three_stamped_inputs(graph, ros, method):
    graph([NodeSpec("allocator_node", "fourws_torque_alloc", "allocator_node",
                    params_files=[str(CFG / "allocator.yaml")],
                    parameters={"method": method})])
    got, pubs = _allocator_io(ros)
    cfg = from_mapping(AllocatorConfig, {**load_ros_params_yaml(str(CFG / "allocator.yaml"),
                                                                "allocator_node"),
                                         "method": method})
    rng = np.random.default_rng(3)
    for k in range(5):
        fz = rng.uniform(1200, 2600, 4)
        fy = rng.uniform(-400, 400, 4)
        mu = rng.uniform(0.4, 1.0, 4)
        t_nm, mz = float(rng.uniform(-300, 600)), float(rng.uniform(-800, 800))
        stamp = ns_to_stamp(k * 10_000_000)
        s = _state(k, 16.0, fz, fy, mu)
        d = DriveCommand(force=t_nm / 0.27, torque=t_nm)
        m = MpcCommand(yaw_moment=mz)
        d.header.stamp = m.header.stamp = stamp
        # Out of order on purpose: the node must wait for all three with the same stamp.
        pubs["m"].publish(m)
        pubs["d"].publish(d)
        ros.spin_until(lambda: False, 0.05)
        assert k * 10_000_000 not in got, "answered before the state arrived"
        pubs["s"].publish(s)
        assert ros.spin_until(lambda k=k: k * 10_000_000 in got, 10.0)
        want = allocate(method, t_nm, mz, fz, fy, mu, cfg).torque_nm
        np.testing.assert_allclose(got[k * 10_000_000].torque, want, rtol=1e-12, atol=1e-9)
        assert got[k * 10_000_000].allocation == method

    k = 5
    stamp = ns_to_stamp(k * 10_000_000)
    s = _state(k, 16.0, [2000.0] * 4, [0.0] * 4, [0.8] * 4)
    d = DriveCommand(force=float("nan"), torque=float("nan"))
    m = MpcCommand(yaw_moment=float("inf"))
    d.header.stamp = m.header.stamp = stamp
    for key, msg in (("s", s), ("d", d), ("m", m)):
        pubs[key].publish(msg)
    assert ros.spin_until(lambda: k * 10_000_000 in got, 10.0), "NaN inputs got no answer"
    out = got[k * 10_000_000]
    assert np.all(np.isfinite(out.torque))
    np.testing.assert_allclose(out.torque, got[4 * 10_000_000].torque)
    assert out.allocation.endswith(":held")


def test_allocator_strays_from_the_future_never_crowd_out_the_current_step(graph, ros):
    """A stray publisher's commands stamped ahead of the run fill the allocator's store; the
    current step's inputs must still be answered (the store once dropped its oldest entry,
    the current step's, and the run then timed out)."""
    from fourws_torque_alloc.allocator_node import MAX_HELD

    graph([NodeSpec("allocator_node", "fourws_torque_alloc", "allocator_node",
                    params_files=[str(CFG / "allocator.yaml")])])
    got, pubs = _allocator_io(ros)

    def step(k: int) -> None:
        d, m = DriveCommand(force=100.0, torque=27.0), MpcCommand(yaw_moment=10.0)
        d.header.stamp = m.header.stamp = ns_to_stamp(k * 10_000_000)
        pubs["m"].publish(m)
        pubs["d"].publish(d)
        pubs["s"].publish(_state(k, 16.0, [2000.0] * 4, [0.0] * 4, [0.8] * 4))

    step(0)
    assert ros.spin_until(lambda: 0 in got, 10.0)
    d = DriveCommand(force=100.0, torque=27.0)
    d.header.stamp = ns_to_stamp(1_000 * 10_000_000)
    pubs["d"].publish(d)                       # the first stray, then the current step's
    for k in (1, 2):                           # drive command, then more strays: the store
        d = DriveCommand(force=100.0, torque=27.0)          # overflows after it arrived
        d.header.stamp = ns_to_stamp(k * 10_000_000)
        pubs["d"].publish(d)
        for j in range(MAX_HELD // 2 + 5):
            s = DriveCommand(force=100.0, torque=27.0)
            s.header.stamp = ns_to_stamp((1_001 + 200 * k + j) * 10_000_000)
            pubs["d"].publish(s)
        m = MpcCommand(yaw_moment=10.0)
        m.header.stamp = ns_to_stamp(k * 10_000_000)
        pubs["m"].publish(m)
        pubs["s"].publish(_state(k, 16.0, [2000.0] * 4, [0.0] * 4, [0.8] * 4))
        assert ros.spin_until(lambda k=k: k * 10_000_000 in got, 10.0), f"step {k} not answered"
    step(3)
    assert ros.spin_until(lambda: 3 * 10_000_000 in got, 10.0)
