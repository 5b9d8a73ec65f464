"""Closed loop on the plant core (slow): the paper's ranking and APCHA's horizon behaviour."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from fourws_bringup.core.closed_loop import run_closed_loop
from fourws_common.resources import config_dir


@pytest.mark.slow
def test_paper_presets_track_and_rank_on_sideslip_as_the_paper():
    """dlc_60_mu05, one cost scaling for all presets (docs/mpc.md): every preset completes the
    lane change within the paper's error scale, and the sideslip ranks as the paper reports
    it (max |β|: MPC-4WS 1.12°, Improved 0.40°; rear steer is there to cut sideslip):
    improved < mpc_4ws < mpc_fws. On our plant the lateral errors of the three are all within
    the path's 2 mm initial offset, so they do not rank (README, "Results")."""
    logs = {c: run_closed_loop("dlc_60_mu05", c) for c in ("improved", "mpc_4ws", "mpc_fws")}
    m = {c: log.metrics() for c, log in logs.items()}
    for c, log in logs.items():
        assert log.completed, (c, log.reason)
        assert m[c]["max_abs_lateral_error_m"] < 0.089, (c, m[c])
    beta = {c: m[c]["max_abs_sideslip_deg"] for c in m}
    assert beta["improved"] < beta["mpc_4ws"] < beta["mpc_fws"], beta


@pytest.mark.slow
def test_tables_6_7_lateral_ranking_holds_where_tracking_outweighs_the_input_penalty():
    """The study of docs/ranking-study.md, at one of its points: with the output sizes of the
    cost scaling at 0.3 x the equal-effect ones (tracking weighted 11x more), the fixed-weight
    presets, whose input penalty is 37x lighter than the fuzzy centre rule's, over-drive the
    steering and the paper's order appears on dlc_60_mu05 (improved < mpc_4ws < mpc_fws on
    max and RMSE lateral error, each step well over the 0.5 mm tie); at the shipped scaling
    (k = 1) the three tie within the path's 2 mm initial offset."""
    scaled = {"scale_y_m": 0.3 * 0.0059, "scale_phi_deg": 0.3 * 0.30}
    m = {c: run_closed_loop("dlc_60_mu05", c, mpc_overrides=scaled).metrics()
         for c in ("improved", "mpc_4ws", "mpc_fws")}
    assert all(m[c]["completed"] for c in m), m
    for key in ("max_abs_lateral_error_m", "rmse_lateral_error_m"):
        e = {c: m[c][key] for c in m}
        assert e["improved"] + 5e-4 < e["mpc_4ws"] and e["mpc_4ws"] + 5e-4 < e["mpc_fws"], e


@pytest.mark.slow
def test_apcha_horizons_grow_on_large_errors_and_return_to_baseline(tmp_path: Path):
    base = config_dir("fourws_sim") / "scenarios" / "dlc_60_mu05.yaml"
    sc = yaml.safe_load(base.read_text(encoding="utf-8"))
    sc["name"] = "dlc_60_mu05_offset"
    sc["initial"]["y_m"] = 0.12                    # e_s = 0.24 ∈ (ε1, 2ε1] at the start
    path = tmp_path / "offset.yaml"
    path.write_text(yaml.safe_dump(sc), encoding="utf-8")
    log = run_closed_loop(str(path), "improved")
    assert log.completed, log.reason
    n_p, n_c = log.mpc["np"], log.mpc["nc"]
    assert list(n_p[:4]) == [14, 16, 18, 20]           # towards N_p^t = 20, ΔN_p per period
    assert n_p.max() >= 20 and n_c.max() >= 8          # grown on the large error
    tail = slice(-200, None)                           # last 2 s: small errors
    assert np.all(n_p[tail] == 12) and np.all(n_c[tail] <= 6)
    assert np.abs(log.mpc["lateral_error"][tail]).max() < 0.02
    assert not log.mpc["fallback"][tail].any()
