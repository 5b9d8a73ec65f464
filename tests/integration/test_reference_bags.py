"""The reference bags in bags/: each is read whole and its metrics equal bags/README.md.

The README's table is the contract: it was written from these bags by
``python tools/make_reference_bags.py`` (after ``fourws paper``); this test recomputes every
number from the bag alone and compares.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from fourws_bringup.bag import read_run
from fourws_bringup.paper import PAPER_RUNS, metrics_from_run

BAGS = Path(__file__).resolve().parents[2] / "bags"
KEYS = ("max_abs_lateral_error_m", "rmse_lateral_error_m", "mae_lateral_error_m",
        "max_abs_heading_error_deg", "rmse_heading_error_deg", "max_abs_sideslip_deg",
        "rmse_sideslip_deg")


def readme_rows() -> dict[str, dict[str, float]]:
    rows = {}
    for line in (BAGS / "README.md").read_text(encoding="utf-8").splitlines():
        m = re.match(r"^\| `([\w@]+)` \|(.+)\|$", line)
        if m:
            cells = [c.strip() for c in m.group(2).split("|")]
            rows[m.group(1)] = dict(zip(("steps",) + KEYS, map(float, cells[:8]), strict=True))
    return rows


def test_every_paper_configuration_has_a_bag_under_5_mb():
    rows = readme_rows()
    for ctrl, scen in PAPER_RUNS:
        name = f"{ctrl}@{scen}"
        assert name in rows, f"{name} missing from bags/README.md"
        files = list((BAGS / name).glob("*.mcap"))
        assert len(files) == 1 and (BAGS / name / "metadata.yaml").is_file(), name
        assert files[0].stat().st_size < 5 * 1024 * 1024, name


@pytest.mark.parametrize("name", [f"{c}@{s}" for c, s in PAPER_RUNS])
def test_bag_metrics_equal_the_readme(name):
    want = readme_rows()[name]
    m = metrics_from_run(read_run(BAGS / name))
    assert m["steps"] == want["steps"]
    for key in KEYS:
        assert m[key] == pytest.approx(want[key], abs=5e-6), key
