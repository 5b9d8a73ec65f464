"""tools/paper_tables.py: Tables 6-8 of both worlds from a sweep's results.csv."""

from __future__ import annotations

import csv
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("paper_tables", ROOT / "tools" / "paper_tables.py")
pt = importlib.util.module_from_spec(spec)
spec.loader.exec_module(pt)

CTRLS = ("mpc_fws", "mpc_4ws", "improved", "ampc_4ws", "ampc_4ws_dyc", "lqr_ff")
KEYS = ("max_abs_lateral_error_m", "rmse_lateral_error_m", "mae_lateral_error_m",
        "max_abs_heading_error_deg", "rmse_heading_error_deg", "max_abs_sideslip_deg",
        "rmse_sideslip_deg")


def _rows(tmp_path):
    rows = []
    for i, c in enumerate(CTRLS):
        for scen in ("bench_dlc_60_mu05", "bench_dlc_90_mu06"):
            for cond, seeds in (("ideal", [0]), ("all", [0, 1, 2])):
                for s in seeds:
                    r = {"controller": c, "scenario": f"/x/{scen}.yaml", "condition": cond,
                         "seed": str(s), "completed": "True", "np_min": "12", "np_max": "14",
                         "nc_min": "4", "nc_max": "6"}
                    for k in KEYS:
                        r[k] = str(0.01 * (i + 1) + 0.001 * s)
                    for w in ("q_y", "q_phi", "r_ddelta", "r_dmz"):
                        r[f"{w}_min"], r[f"{w}_max"] = "100", str(200 + s)
                    rows.append(r)
    rows[-1]["completed"] = "False"          # lqr_ff, 90 km/h, all, seed 2: aborted
    path = tmp_path / "results.csv"
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return pt.read_rows(path)


def test_median_and_worst_over_completed_seeds(tmp_path):
    rows = _rows(tmp_path)
    rs = pt.pick(rows, "improved", "dlc_60_mu05", "all")
    assert len(rs) == 3
    assert pt.median_worst(rs, "max_abs_lateral_error_m") == pytest.approx((0.031, 0.032))
    lq = pt.pick(rows, "lqr_ff", "dlc_90_mu06", "all")
    assert pt.median_worst(lq, "max_abs_lateral_error_m") == pytest.approx((0.0605, 0.061))


def test_both_worlds_and_all_three_tables_with_ranges(tmp_path):
    text = pt.tables(_rows(tmp_path), margins=False)
    for world in ("ideal", "realistic"):
        for t in ("Table 6", "Table 7", "Table 8"):
            assert f"### {t}" in text and f"({world})" in text
    assert "| improved | fourws | 0.0310 (0.0320) |" in text
    assert "| lqr_ff | fourws | 0.0605 (0.0610) |" in text and "| 3 (1) |" in text
    assert "q_Y 100-202" in text and "N_p 12-14, N_c 4-6" in text
    # ranking by median: mpc_fws (0.01) < mpc_4ws (0.02) < improved (0.03)
    assert "mpc_fws < mpc_4ws < improved; paper improved < mpc_4ws < mpc_fws" in text
