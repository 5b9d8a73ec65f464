"""Two complete graphs in two namespaces of one ROS domain, at the same time.

Topics are relative (``vehicle/state``), so ``fourws run --namespace car1`` puts every node
and topic under /car1; ``/diagnostics`` stays global, and each simulation's clock moves to
``/car1/clock`` so two simulated cars do not mix their times. Two runs of different
controllers share one domain; each records only its own namespace's graph, and each records
the same run, bit for bit, as the same controller alone in a domain of its own.
"""

from __future__ import annotations

import json
import os
import subprocess

import pytest
from conftest import cut_scenario

from fourws_bringup.bag.reader import McapBag
from fourws_bringup.bag.run_data import read_run

pytestmark = [pytest.mark.integration, pytest.mark.slow]
RUNS = {"car1": "mpc_4ws", "car2": "improved"}


def _fourws_run(scenario, controller, out, *extra) -> subprocess.Popen:
    return subprocess.Popen(["fourws", "run", "--scenario", str(scenario), "--controller",
                             controller, "--out", str(out), "--no-plots", *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})


def test_two_graphs_in_two_namespaces_of_one_domain(domain_id, tmp_path):
    scenario = cut_scenario(tmp_path, 50.0)
    shared = {ns: _fourws_run(scenario, c, tmp_path / ns, "--namespace", ns,
                              "--domain-id", str(domain_id)) for ns, c in RUNS.items()}
    for ns, p in shared.items():
        out, err = p.communicate(timeout=600)
        assert p.returncode == 0, (ns, err[-3000:])
    for ns, c in RUNS.items():
        alone = _fourws_run(scenario, c, tmp_path / f"{c}-alone")  # a free domain of its own
        _, err = alone.communicate(timeout=600)
        assert alone.returncode == 0, err[-3000:]
        with McapBag(tmp_path / ns / "bag") as bag:
            names = set(bag.channels)
        other = next(n for n in RUNS if n != ns)
        assert f"/{ns}/vehicle/state" in names and f"/{ns}/control/mpc_command" in names
        assert not any(n.startswith(f"/{other}/") for n in names), names
        # each simulated car has its own clock (graph.clock_remap); /diagnostics is global
        assert f"/{ns}/clock" in names and "/clock" not in names and "/diagnostics" in names
        # ... but a car's bag holds its own nodes' diagnostics only (issue 41, item 10)
        with McapBag(tmp_path / ns / "bag") as bag:
            statuses = {s.name.split(":")[0] for _t, _l, _p, msg in bag.decoded(["/diagnostics"])
                        for s in msg.status}
        assert statuses and all(s.startswith(f"/{ns}/") for s in statuses), statuses
        m = json.loads((tmp_path / ns / "metrics.json").read_text())
        m_alone = json.loads((tmp_path / f"{c}-alone" / "metrics.json").read_text())
        assert m["namespace"] == f"/{ns}" and m["completed"], m
        for key in ("max_abs_lateral_error_m", "rmse_lateral_error_m", "max_abs_sideslip_deg",
                    "steps"):
            assert m[key] == m_alone[key], (ns, key)
        run, ref = read_run(tmp_path / ns), read_run(tmp_path / f"{c}-alone")
        assert run.steps == ref.steps > 250
        for key in ("x", "y", "yaw", "vx", "vy", "yaw_rate"):
            assert run.state[key].tolist() == ref.state[key].tolist(), (ns, key)
        for key in ("delta_front", "delta_rear", "yaw_moment"):
            assert run.mpc_command[key].tolist() == ref.mpc_command[key].tolist(), (ns, key)
