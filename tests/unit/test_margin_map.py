"""studies/margin_map/margin_map.py: the tuning grid's margins, on the very loops `fourws tune`
keeps by."""

from __future__ import annotations

import dataclasses
import importlib.util
import math
import re
import sys
from pathlib import Path

from fourws_bringup import tuning
from fourws_bringup.core.margins import margins

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("margin_map",
                                               ROOT / "studies" / "margin_map" / "margin_map.py")
mm = importlib.util.module_from_spec(_spec)
sys.modules["margin_map"] = mm          # its dataclass looks itself up there
_spec.loader.exec_module(mm)


def _small_spec(tmp_path: Path, group: str = "lqr_ff", exponents: str = "[-8, 0]"
                ) -> tuning.TuningSpec:
    """The shipped spec cut to one group, one speed and a few grid points (for lqr_ff:
    Bryson's maxima /16, a gain the loop cannot hold, and ×1)."""
    text = (ROOT / "benchmarks" / "tuning.yaml").read_text(encoding="utf-8")
    text, cut = re.subn(r"grid_exponents: \[[-0-9, ]+\]", f"grid_exponents: {exponents}",
                        text, count=1)
    assert cut == 1                              # the cut must cut
    for old, new in (("speeds_kmh: [60.0, 90.0]", "speeds_kmh: [60.0]"),
                     ("scenarios: [sine_50_mu08, scenarios/", "scenarios: [sine_50_mu08, "
                      + str(ROOT / "benchmarks" / "scenarios") + "/")):
        assert old in text, old                  # the cut must cut
        text = text.replace(old, new)
    path = tmp_path / "tuning.yaml"
    path.write_text(text, encoding="utf-8")
    spec = tuning.load_tuning_spec(path)
    return dataclasses.replace(spec, groups=tuple(g for g in spec.groups if g.name == group))


def test_the_map_reads_the_loops_the_tuning_keeps_by(tmp_path):
    spec = _small_spec(tmp_path)
    group = spec.groups[0]
    table = mm.margin_map(spec)[group.name]
    assert [dict(r.values) for r in table] == tuning.candidates(spec, group)
    for row in table:
        assert row.rho == tuning.worst_radius(spec, group, row.values)   # step 2's ρ, exactly
        direct = [analyse(margins) for *_, analyse in tuning.loops(spec, group, row.values)]
        assert len(direct) == 2                                        # ideal and told
        if row.rho < 1.0:
            assert row.gain_margin_db == min(m.gain_margin_db or math.inf for m in direct)
            assert row.phase_margin_deg == min(m.phase_margin_deg for m in direct)
            assert row.delay_margin_ms == min(m.delay_margin_ms for m in direct)


def test_a_stable_loop_has_positive_margins_and_an_unstable_one_meets_no_floor(tmp_path):
    spec = _small_spec(tmp_path)
    table = mm.margin_map(spec)["lqr_ff"]
    unstable = [r for r in table if r.rho >= 1.0]
    stable = [r for r in table if r.rho < 1.0]
    assert unstable and stable                     # e1,max 3 mm spins; 5 cm holds
    for r in stable:
        assert r.gain_margin_db > 0 and r.phase_margin_deg > 0 and r.delay_margin_ms > 0
    for r in unstable:
        assert r.gain_margin_db == r.phase_margin_deg == -math.inf
        assert not r.meets(2.0, -1e9, -1e9)       # no floor is low enough
    r = stable[0]
    assert math.isfinite(r.gain_margin_db) and math.isfinite(r.phase_margin_deg)
    assert r.meets(1.0, 0.0, 0.0)
    assert not r.meets(1.0, r.gain_margin_db + 0.1, 0.0)
    assert not r.meets(1.0, 0.0, r.phase_margin_deg + 0.1)
    assert not r.meets(r.rho - 1e-6, 0.0, 0.0)


def test_the_report_counts_what_it_lists(tmp_path):
    spec = _small_spec(tmp_path)
    table = mm.margin_map(spec)
    text = mm.markdown("tuning.yaml", spec, table, 0.0, 0.0)
    kept = sum(r.rho <= spec.max_spectral_radius for r in table["lqr_ff"])
    assert f"{kept} of 4 candidates kept, {kept} meet the floor" in text
    assert text.count("| unstable |") >= 1
    # the cut grid holds Bryson's package defaults, not the shipped e1,max 0.1 m
    assert "(shipped)" not in text.split("## lqr_ff")[1]
    shipped = tuning.shipped(spec.groups[0])
    cut = dataclasses.replace(spec, grid_exponents=(0, 2))
    assert shipped in tuning.candidates(cut, cut.groups[0])
    assert "(shipped)" in mm.markdown("tuning.yaml", cut, mm.margin_map(cut), 0.0, 0.0)


def test_a_group_is_as_good_as_its_worst_member_and_names_it(tmp_path):
    """The paper's five presets at s_Y, s_φ ×1/16 (a kept candidate): the group's GM and PM
    are the smallest of its members', and the loop named as binding has that GM."""
    spec = _small_spec(tmp_path, group="mpc", exponents="[-8]")
    (row,) = mm.margin_map(spec)["mpc"]
    assert set(row.by_controller) == set(spec.groups[0].controllers)
    assert row.gain_margin_db == min(gm for gm, _ in row.by_controller.values())
    assert row.phase_margin_deg == min(pm for _, pm in row.by_controller.values())
    member = row.binding.split(" (")[0]
    assert row.by_controller[member][0] == row.gain_margin_db
    text = mm.markdown("tuning.yaml", spec, {"mpc": [row]}, 0.0, 0.0)
    assert "Each controller alone" in text
