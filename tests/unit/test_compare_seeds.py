"""studies/compare_seeds.py: the paired seed comparison of two controllers."""

from __future__ import annotations

import csv
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("compare_seeds",
                                              ROOT / "studies" / "compare_seeds.py")
cs = importlib.util.module_from_spec(spec)
spec.loader.exec_module(cs)


def _write(tmp_path, values):
    """A results.csv of ``values``: (controller, seed[, condition]) -> metric (None: the run
    did not complete); the condition is "all" where the key leaves it out."""
    path = tmp_path / "results.csv"
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, ["controller", "scenario", "condition", "seed", "completed",
                               "max_abs_lateral_error_m"])
        w.writeheader()
        for (c, seed, *cond), v in values.items():
            w.writerow({"controller": c, "scenario": "/x/s.yaml",
                        "condition": cond[0] if cond else "all",
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


def test_non_inferiority_is_shown_only_when_the_interval_lies_below_the_margin(tmp_path):
    """A controller worse by 1 mm ± 2 mm over 40 seeds: non-inferior at a 5 mm margin, not
    at 1 mm (the interval holds the margin); the verdict agrees with the interval's end."""
    vals = {}
    for s in range(40):
        vals[("ref", s)] = 0.060 + 0.0005 * (s % 7)
        vals[("a", s)] = vals[("ref", s)] + 0.001 + 0.002 * (1 if s % 2 else -1)
    rows = cs.read_rows(_write(tmp_path, vals), "max_abs_lateral_error_m", "all")
    (wide,) = cs.compare(rows, "ref", margin=0.005)
    (tight,) = cs.compare(rows, "ref", margin=0.001)
    assert wide["mean_diff"] == pytest.approx(0.001, abs=1e-9)
    assert wide["mean_diff_ci95"][1] < 0.005 and wide["p_noninferior"] < 0.025
    assert tight["mean_diff_ci95"][1] > 0.001 and tight["p_noninferior"] > 0.025
    md = cs.markdown([wide], "max_abs_lateral_error_m", 1000.0, "mm")
    assert "yes at 5.0" in md
    assert "not shown at 1.0" in cs.markdown([tight], "max_abs_lateral_error_m", 1000.0, "mm")
    assert "non-inferior" not in cs.markdown(cs.compare(rows, "ref"),
                                             "max_abs_lateral_error_m", 1000.0, "mm")


def test_between_pairs_each_controller_with_itself_under_the_other_condition(tmp_path):
    """``--between BASE OTHER``: a controller's seeds under OTHER against its own under BASE;
    a controller missing from one condition is left out, and none in common is an error."""
    vals = {}
    for s in range(8):
        for cond, shift in (("base", 0.0), ("retuned", 0.003)):
            vals[("a", s, cond)] = 0.05 + 0.001 * s + shift + 0.0002 * (s % 2)
        vals[("b", s, "base")] = 0.01
    path = _write(tmp_path, vals)
    base, other = (cs.read_rows(path, "max_abs_lateral_error_m", c)
                   for c in ("base", "retuned"))
    (r,) = cs.compare_conditions(base, other, "base", "retuned")
    assert (r["controller"], r["reference"]) == ("a retuned", "a base")
    assert r["pairs"] == 8 and r["better"] == 0
    assert r["mean_diff"] == pytest.approx(0.003)
    assert cs.main([str(path), "--between", "base", "retuned"]) == 0
    assert cs.main([str(path), "--between", "base", "nowhere"]) == 2


def test_the_reference_may_come_from_another_condition(tmp_path):
    """``--reference-condition``: a controller's runs under a diagnostic condition against the
    reference's under the shipped one, paired by seed; without it the rows of the condition
    hold no reference and the tool says so."""
    vals = {}
    for s in range(8):
        vals[("ref", s, "all")] = 0.060 + 0.001 * s
        vals[("ref", s, "soft")] = 1.0                 # must not be used
        vals[("a", s, "soft")] = 0.058 + 0.001 * s + 0.0002 * (s % 2)
    path = _write(tmp_path, vals)
    rows = cs.with_reference_from(cs.read_rows(path, "max_abs_lateral_error_m", "soft"),
                                  cs.read_rows(path, "max_abs_lateral_error_m", "all"), "ref")
    (r,) = cs.compare(rows, "ref")
    assert r["pairs"] == 8 and r["better"] == 8
    assert r["mean_diff"] == pytest.approx(-0.0019)
    assert cs.main([str(path), "--condition", "soft", "--reference", "ref",
                    "--reference-condition", "all"]) == 0
    vals = {k: v for k, v in vals.items() if not (k[0] == "ref" and k[2] == "soft")}
    assert cs.main([str(_write(tmp_path, vals)), "--condition", "soft",
                    "--reference", "ref"]) == 2
