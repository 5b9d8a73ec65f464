"""Closed loop on the plant core (slow): the paper's ranking and APCHA's horizon behaviour."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from fourws_bringup.core.closed_loop import run_closed_loop
from fourws_common.resources import config_dir


def _without_relaxation(tmp_path: Path, name: str) -> str:
    """The scenario with the plant's tyre relaxation turned off (p_Ty1 = 0)."""
    sc = yaml.safe_load((config_dir("fourws_sim") / "scenarios" / f"{name}.yaml").read_text(
        encoding="utf-8"))
    sc["name"] = f"{name}_no_relaxation"
    sc["vehicle"] = {**(sc.get("vehicle") or {}), "tyre_relaxation_peak_over_radius": 0.0}
    path = tmp_path / f"{name}_no_relaxation.yaml"
    path.write_text(yaml.safe_dump(sc), encoding="utf-8")
    return str(path)


def _order_ok(m: dict, key: str) -> bool:
    """improved < mpc_4ws < mpc_fws on ``key``, each step beyond 0.5 mm; an aborted run last."""
    e = {c: (m[c][key] if m[c]["completed"] else np.inf) for c in m}
    return e["improved"] + 5e-4 < e["mpc_4ws"] and e["mpc_4ws"] + 5e-4 < e["mpc_fws"]


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["dlc_60_mu05", "dlc_90_mu06"])
def test_tables_6_7_lateral_ranking_comes_from_the_unmodelled_tyre_lag(scenario, tmp_path):
    """One cost scaling for all presets (docs/mpc.md). On the plant's tyres, whose lateral
    force lags the slip angle over the relaxation length (13 ms at 60 km/h), the lateral error
    ranks as Tables 6-7 (improved < mpc_4ws < mpc_fws on max and RMSE eY) and improved stays
    within the paper's 0.089 m: the fixed weights' 37x lighter input penalty over-drives the
    steering against a lag eq. (1) does not contain. The same runs with the lag off tie
    within 0.5 mm: the separation is the lag's, not the path's."""
    presets = ("improved", "mpc_4ws", "mpc_fws")
    m = {c: run_closed_loop(scenario, c).metrics() for c in presets}
    assert m["improved"]["completed"] and m["mpc_4ws"]["completed"], m
    assert m["improved"]["max_abs_lateral_error_m"] < 0.089, m["improved"]
    for key in ("max_abs_lateral_error_m", "rmse_lateral_error_m"):
        assert _order_ok(m, key), (key, m)
    assert m["improved"]["max_abs_sideslip_deg"] < m["mpc_4ws"]["max_abs_sideslip_deg"]
    path = _without_relaxation(tmp_path, scenario)
    off = {c: run_closed_loop(path, c).metrics() for c in presets}
    e = [off[c]["max_abs_lateral_error_m"] for c in presets]
    assert all(off[c]["completed"] for c in presets), off
    assert max(e) - min(e) < 5e-4, e


@pytest.mark.slow
def test_table_8_yaw_moment_lowers_lateral_error_and_sideslip_the_allocation_ties():
    """Table 8 on dlc_60_mu05, the car started on the path: adding the direct yaw moment to
    AMPC-4WS lowers max and RMSE eY and max sideslip (paper: 171 → 124 mm, 1.51° → 0.86°).
    Rule-based and load-ratio allocation of that moment tie (paper: 124 → 89 mm): they only
    differ in the front/rear split of each side, by a few N·m per wheel
    (tests/integration/test_reference_bags.py measures it on the bags)."""
    m, mz = {}, {}
    for c in ("improved", "ampc_4ws_dyc", "ampc_4ws"):
        log = run_closed_loop("dlc_60_mu05", c)
        m[c], mz[c] = log.metrics(), float(np.abs(log.mpc["yaw_moment"]).max())
        assert m[c]["completed"], m[c]
    assert mz["ampc_4ws"] == 0.0 and 100.0 < mz["improved"] < 500.0, mz
    for key in ("max_abs_lateral_error_m", "rmse_lateral_error_m", "max_abs_sideslip_deg"):
        for dyc in ("improved", "ampc_4ws_dyc"):
            assert m[dyc][key] < 0.98 * m["ampc_4ws"][key], (key, m)
        assert m["improved"][key] == pytest.approx(m["ampc_4ws_dyc"][key], rel=0.01), (key, m)


@pytest.mark.slow
def test_apcha_horizons_grow_on_large_errors_and_return_to_baseline(tmp_path: Path):
    base = config_dir("fourws_sim") / "scenarios" / "dlc_60_mu05.yaml"
    sc = yaml.safe_load(base.read_text(encoding="utf-8"))
    sc["name"] = "dlc_60_mu05_offset"
    sc["initial"] = {"x_m": 0.0, "y_m": 0.12, "yaw_deg": 0.0}  # e_s ≈ 0.24 ∈ (ε1, 2ε1]
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
