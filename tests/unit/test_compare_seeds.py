"""tools/compare_seeds.py: the paired seed comparison of two controllers."""

from __future__ import annotations

import csv
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("compare_seeds",
                                              ROOT / "tools" / "compare_seeds.py")
cs = importlib.util.module_from_spec(spec)
spec.loader.exec_module(cs)


def _write(tmp_path, values):
    path = tmp_path / "results.csv"
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, ["controller", "scenario", "condition", "seed", "completed",
                               "max_abs_lateral_error_m"])
        w.writeheader()
        for (c, seed), v in values.items():
            w.writerow({"controller": c, "scenario": "/x/s.yaml", "condition": "all",
                        "seed": seed, "completed": str(v is not None),
                        "max_abs_lateral_error_m": "" if v is None else v})
    return path


def test_a_controller_better_on_every_seed_is_significant_and_counted(tmp_path):
    vals = {}
    for s in range(10):
        vals[("ref", s)] = 0.060 + 0.001 * s
        vals[("a", s)] = 0.055 + 0.001 * s + 0.0001 * (s % 3)     # 4-5 mm better, always
    table = cs.compare(cs.read_rows(_write(tmp_path, vals), "max_abs_lateral_error_m", "all"),
                       "ref")
    (r,) = table
    assert r["better"] == 10 and r["pairs"] == 10 and r["lost"] == 0
    assert r["paired_median_diff"] == pytest.approx(-0.0049, abs=2e-4)
    assert r["p"] < 0.01
    lo, hi = r["mean_diff_ci95"]          # the interval holds the shift and excludes no change
    assert lo < r["mean_diff"] < hi < 0.0 and lo < -0.0049 < hi
    assert "10 of 10" in cs.markdown(table, "max_abs_lateral_error_m", 1000.0, "mm")


def test_a_tie_is_not_significant_and_a_lost_run_is_counted_not_paired(tmp_path):
    vals = {}
    for s in range(10):
        vals[("ref", s)] = 0.060
        vals[("a", s)] = 0.060 + (0.002 if s % 2 else -0.002)
    vals[("a", 3)] = None                                          # did not complete
    (r,) = cs.compare(cs.read_rows(_write(tmp_path, vals), "max_abs_lateral_error_m", None),
                      "ref")
    assert r["lost"] == 1 and r["pairs"] == 9 and r["p"] > 0.5
    lo, hi = r["mean_diff_ci95"]
    assert lo < 0.0 < hi                  # a tie: the interval holds zero
