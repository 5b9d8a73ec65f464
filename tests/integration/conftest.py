"""Integration-test fixtures: a private ROS domain per test, real processes, nothing left over.

Every test gets its own ``ROS_DOMAIN_ID`` (an exclusive lock file, see
``fourws_bringup.supervisor.DomainLease``) with discovery kept on this host, so parallel runs
never meet. ``graph`` starts nodes through the real supervisor and, at teardown, stops them
and checks the process table that none of their processes survived. ``ros`` gives the test
its own rclpy context and node in the same domain.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.integration

HERE = Path(__file__).resolve().parent


def _require_workspace() -> None:
    if not os.environ.get("AMENT_PREFIX_PATH") or "fourws_msgs" not in os.environ.get(
        "AMENT_PREFIX_PATH", ""
    ):
        pytest.fail("integration tests need the built workspace: run them via 'make test' "
                    "or after 'source ros_ws/env.sh'")


def pid_alive(pid: int) -> bool:
    """True if the process exists and is not a zombie (checked in /proc, not by a flag)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
            state = fh.read().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False
    return state != "Z"


def cut_scenario(folder: Path, end_x_m: float) -> Path:
    """dlc_60_mu05 cut at ``end_x_m`` (a YAML in ``folder``): a short run of the real scenario."""
    import yaml

    from fourws_common.resources import config_dir

    spec = yaml.safe_load((config_dir("fourws_sim") / "scenarios" / "dlc_60_mu05.yaml")
                          .read_text())
    spec.update(name=f"dlc_60_to_{end_x_m:.0f}m", end_x_m=end_x_m, duration_s=15.0)
    path = folder / f"dlc_60_to_{end_x_m:.0f}m.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def script_node(script: str, name: str) -> dict:
    """NodeSpec kwargs for one of the small test programs in tests/integration/nodes/."""
    return {"name": name, "package": "", "executable": "",
            "argv": [sys.executable, str(HERE / "nodes" / script)]}


@pytest.fixture
def domain_id():
    _require_workspace()
    from fourws_bringup.supervisor import DomainLease

    lease = DomainLease()
    yield lease.domain_id
    lease.release()


@pytest.fixture
def graph(domain_id, tmp_path):
    """Factory: ``graph(specs, timeout_s=30)`` -> started Supervisor; stopped at teardown."""
    from fourws_bringup.supervisor import Supervisor

    sups: list[Supervisor] = []

    def make(specs, timeout_s: float = 30.0, start: bool = True):
        sup = Supervisor(specs, domain_id, tmp_path / f"logs{len(sups)}")
        sups.append(sup)
        if start:
            sup.start(timeout_s=timeout_s)
        return sup

    yield make
    pids = []
    for sup in sups:
        pids += sup.pids()
        sup.stop()
    deadline = time.monotonic() + 5.0
    while any(pid_alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    leftover = [p for p in pids if pid_alive(p)]
    assert not leftover, f"processes outlived the test: {leftover}"


@pytest.fixture
def ros(domain_id):
    """An rclpy context and node for the test itself, in the test's domain."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    node = rclpy.create_node(f"test_client_{os.getpid()}", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)

    class Ros:
        pass

    r = Ros()
    r.node, r.executor, r.context = node, ex, ctx

    def spin_until(pred, timeout_s: float = 20.0) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if pred():
                return True
            ex.spin_once(timeout_sec=0.02)
        return pred()

    r.spin_until = spin_until
    yield r
    ex.shutdown()
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)
