"""tools/noise_floor.py: a run's max |eY| against the localisation error of its seed."""

from __future__ import annotations

import csv
import importlib.util
from pathlib import Path

import pytest
from plant_helpers import plant_output

from fourws_sim.core.sensing import NoiseSpec, Sensors

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("noise_floor", ROOT / "tools" / "noise_floor.py")
nf = importlib.util.module_from_spec(spec)
spec.loader.exec_module(nf)

NOISE = {"x": NoiseSpec(0.02, 1.0), "y": NoiseSpec(0.02, 1.0), "yaw_rate": NoiseSpec(0.002)}


def test_the_floor_is_the_error_the_plant_gave_the_controllers():
    """The same stream as the bench's Sensors for that seed: a state at y = 0 measured by the
    plant's sensors shows exactly the errors the floor is the largest of."""
    sensors = Sensors(NOISE, 0.01, seed=7)
    seen = [abs(sensors.measure(plant_output()).y) for _ in range(500)]
    assert nf.floor_m(NOISE, 7, 500, 0.01) == pytest.approx(max(seen), abs=0.0)
    assert nf.floor_m(NOISE, 8, 500, 0.01) != max(seen)           # another seed, another draw
    assert nf.floor_m({"x": NoiseSpec(0.02)}, 7, 500, 0.01) == 0.0  # no noise on y: no floor


def test_a_run_on_the_floor_has_ratio_and_correlation_one(tmp_path):
    path = tmp_path / "results.csv"
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, ["controller", "scenario", "condition", "seed", "completed",
                               "max_abs_lateral_error_m", "steps"])
        w.writeheader()
        for seed in range(6):
            floor = nf.floor_m(NOISE, seed, 300, 0.01)
            w.writerow({"controller": "holds", "scenario": "s.yaml", "condition": "all",
                        "seed": seed, "completed": "True", "steps": 300,
                        "max_abs_lateral_error_m": floor})
            w.writerow({"controller": "own", "scenario": "s.yaml", "condition": "all",
                        "seed": seed, "completed": "True", "steps": 300,
                        "max_abs_lateral_error_m": 0.05 + 0.001 * (seed % 2)})
    holds, own = nf.analyse(path, NOISE, 0.01, "y", "all")
    assert holds["controller"] == "holds" and holds["ratio"] == pytest.approx(1.0)
    assert holds["corr"] == pytest.approx(1.0)
    assert abs(own["corr"]) < 0.9
    assert "| s | holds | 6 |" in nf.markdown([holds, own], "y")


def test_a_condition_with_a_localisation_filter_is_labelled_raw_floor(tmp_path):
    """Behind a filter the controllers did not receive the raw fix the floor is drawn from:
    the section says so, and only for that condition."""
    spec_path = tmp_path / "spec.yaml"
    spec_path.write_text(
        "seeds: [0, 1, 2]\ngroups:\n  - controllers: [improved]\n"
        "    scenarios: [dlc_60_mu05]\n    conditions:\n      all: realistic\n"
        "      all_ekf: {base: realistic, localisation: ekf}\n", encoding="utf-8")
    path = tmp_path / "results.csv"
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, ["controller", "scenario", "condition", "seed", "completed",
                               "max_abs_lateral_error_m", "steps"])
        w.writeheader()
        for cond in ("all", "all_ekf"):
            for seed in range(3):
                w.writerow({"controller": "improved", "scenario": "dlc_60_mu05.yaml",
                            "condition": cond, "seed": seed, "completed": "True",
                            "steps": 200, "max_abs_lateral_error_m": 0.05})
    text = nf.spec_section(path, spec_path)
    plain, filtered = text.split("### all_ekf")
    assert "### all\n" in plain and "raw fix" not in plain
    assert "received its estimate, not the raw fix" in filtered
