"""The whole graph over real topics: plant, MPC, speed PID, allocator and recorder.

- The lockstep graph is the in-process closed loop (``fourws_bringup.core.closed_loop``)
  distributed over processes: the recorded states equal the in-process ones to 1e-9.
- On the paper's 60 km/h, μ = 0.5 lane change the controllers rank as in Table 6 on max |eY|
  and RMSE eY: improved < mpc_4ws < mpc_fws.
"""

from __future__ import annotations

import numpy as np
import pytest

from fourws_bringup.bag import read_run
from fourws_bringup.core.closed_loop import run_closed_loop
from fourws_bringup.paper import metrics_from_run
from fourws_bringup.runner import run_graph

pytestmark = [pytest.mark.integration, pytest.mark.slow]


def _graph_run(tmp_path, scenario: str, controller: str):
    out = tmp_path / f"{controller}@{scenario}"
    out.mkdir()
    outcome = run_graph(scenario, controller, out, progress=False)
    assert outcome.completed, outcome.reason
    return read_run(out)


def test_graph_reproduces_the_in_process_closed_loop(tmp_path):
    run = _graph_run(tmp_path, "dlc_60_mu05", "mpc_4ws")
    log = run_closed_loop("dlc_60_mu05", "mpc_4ws")
    n = min(run.steps, log.steps)
    assert n > 500 and abs(run.steps - (log.steps + 1)) <= 1
    for key in ("x", "y", "yaw", "vx", "vy", "yaw_rate"):
        np.testing.assert_allclose(run.state[key][:n], log.state[key][:n], rtol=0, atol=1e-9,
                                   err_msg=key)
    np.testing.assert_allclose(run.mpc_command["delta_front"][:n], log.mpc["delta_front"][:n],
                               rtol=0, atol=1e-9)


def test_controllers_rank_as_in_table_6_over_topics(tmp_path):
    m = {c: metrics_from_run(_graph_run(tmp_path, "dlc_60_mu05", c))
         for c in ("mpc_fws", "mpc_4ws", "improved")}
    for key in ("max_abs_lateral_error_m", "rmse_lateral_error_m"):
        assert m["improved"][key] < m["mpc_4ws"][key] < m["mpc_fws"][key], (key, m)
    assert m["improved"]["max_abs_lateral_error_m"] < 0.15
