"""Nodes and the in-process loop take every parameter the same way.

Each controller node is built in a process of its own from the very ``--params-file`` list the
runner passes (``configs.params_files``) plus a ``-p`` override of every core parameter (a
value other than the file's), and prints the configuration its core got; it must equal what
``fourws_bringup.core.configs`` loads for the in-process loop with the same overrides. For
the MPC the reference it builds from a ReferenceTrajectory is checked too: ``mpc_node`` once
dropped ``ref_search_back``/``ref_search_ahead`` there (fixed in 7b806b8), so changing them
moved only the in-process loop; this test would have caught it.
"""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import textwrap

import pytest

from fourws_bringup.core.configs import (
    load_allocator_config,
    load_mpc_config,
    load_pid_config,
    params_files,
)

pytestmark = pytest.mark.integration
CONTROLLER = "improved"

SCRIPT = textwrap.dedent("""
    import dataclasses, json, sys
    import numpy as np
    import rclpy
    node_name, args = sys.argv[1], sys.argv[2:]
    rclpy.init(args=["--ros-args", *args])
    if node_name == "mpc_node":
        from fourws_mpc.mpc_node import MpcNode as Cls
    elif node_name == "speed_pid_node":
        from fourws_torque_alloc.speed_pid_node import SpeedPidNode as Cls
    else:
        from fourws_torque_alloc.allocator_node import AllocatorNode as Cls
    node = Cls()
    out = {"config": dataclasses.asdict(node.params.config)}
    if node_name == "mpc_node":
        from fourws_msgs.msg import ReferenceTrajectory
        x = np.linspace(0.0, 100.0, 1001)
        msg = ReferenceTrajectory(x=x.tolist(), y=np.zeros_like(x).tolist(),
                                  yaw=np.zeros_like(x).tolist(),
                                  curvature=np.zeros_like(x).tolist(),
                                  speed=np.full_like(x, 10.0).tolist())
        node._on_ref(msg)
        out["controller_config"] = dataclasses.asdict(node.ctrl.cfg)
        out["ref_window"] = [node.ref.search_back, node.ref.search_ahead]
    print("RESULT " + json.dumps(out, default=str))
    node.destroy_node()
    rclpy.shutdown()
""")


def _other(value, hi=None):
    """A valid value other than ``value`` for an override (same type): +1 %, or −1 % where
    +1 % would leave the field's range (``hi``: its upper end)."""
    if isinstance(value, bool):
        return value
    if isinstance(value, int):
        return value + 1
    if isinstance(value, float):
        if not value:
            return 0.001
        return value * 0.99 if hi is not None and value * 1.01 > hi else value * 1.01
    return value


def _node_config(node: str, overrides: dict, domain_id: int) -> dict:
    args = []
    for f in params_files(node, CONTROLLER):
        args += ["--params-file", str(f)]
    for k, v in overrides.items():
        args += ["-p", f"{k}:={json.dumps(v) if not isinstance(v, str) else v}"]
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id))
    r = subprocess.run([sys.executable, "-c", SCRIPT, node, *args], capture_output=True,
                       text=True, timeout=120, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    line = next(ln for ln in r.stdout.splitlines() if ln.startswith("RESULT "))
    return json.loads(line.removeprefix("RESULT "))


# numeric parameters whose +1 % / +1 would break a cross-field rule or a choice
_KEEP = {"np_baseline", "nc_baseline", "np_min", "np_max", "nc_min", "nc_max", "dt_s",
         "fuzzy_grid_y", "fuzzy_grid_phi", "fuzzy_out_points", "apcha_lambda",
         "max_total_torque_nm", "min_total_torque_nm"}


def _overrides(cfg) -> dict:
    out = {}
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        o = _other(v, f.metadata.get("hi"))
        if f.name not in _KEEP and o != v:
            out[f.name] = o
    return out


def test_mpc_node_takes_every_parameter_as_the_in_process_loop(domain_id):
    base = load_mpc_config(CONTROLLER)
    ov = _overrides(base)
    assert {"ref_search_back", "ref_search_ahead", "mass_kg"} <= set(ov)
    expected = dataclasses.asdict(load_mpc_config(CONTROLLER, ov))
    got = _node_config("mpc_node", ov, domain_id)
    assert got["config"] == json.loads(json.dumps(expected, default=str))
    assert got["controller_config"] == got["config"]
    assert got["ref_window"] == [ov["ref_search_back"], ov["ref_search_ahead"]]


@pytest.mark.parametrize("node", ["speed_pid_node", "allocator_node"])
def test_lower_layer_nodes_take_every_parameter_as_the_in_process_loop(node, domain_id):
    load = load_pid_config if node == "speed_pid_node" else \
        (lambda: load_allocator_config(CONTROLLER))
    base = load()
    ov = _overrides(base)
    assert ov
    got = _node_config(node, ov, domain_id)["config"]
    expected = dataclasses.asdict(dataclasses.replace(base, **ov))
    # the node's config may hold node-level keys beyond the core's
    assert {k: got[k] for k in expected} == json.loads(json.dumps(expected, default=str))
