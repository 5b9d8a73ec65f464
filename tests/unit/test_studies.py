"""studies/: every study spec still loads, and every scenario and preset it names resolves.

A study is a record (its README holds the question, the command and the result); nothing
here checks its numbers. A spec is a sweep spec (``fourws sweep``) or, with
``grid_exponents``, a tuning spec (``fourws tune``); every other YAML under studies/ is a
study preset that some spec names."""

from __future__ import annotations

from pathlib import Path

import pytest

from fourws_bringup import tuning
from fourws_bringup.core.conditions import condition_from_mapping, condition_mapping
from fourws_bringup.core.configs import is_yaml_path, load_mpc_config
from fourws_bringup.sweep import load_spec
from fourws_common.params import read_yaml_file
from fourws_sim.core.scenario import load_scenario

STUDIES = Path(__file__).resolve().parents[2] / "studies"
YAMLS = sorted(STUDIES.rglob("*.yaml"))


def _is_preset(path: Path) -> bool:
    return any(str(k).endswith("mpc_node") for k in read_yaml_file(path))


SPECS = [p for p in YAMLS if not _is_preset(p)]
PRESETS = [p for p in YAMLS if _is_preset(p)]


def _named(path: Path) -> tuple[set[str], set[str], list]:
    """The controllers, scenarios and conditions (with their MPC overrides) of a spec."""
    if "grid_exponents" in read_yaml_file(path):
        spec = tuning.load_tuning_spec(path)
        conditions = [condition_from_mapping({**condition_mapping(raw), "name": str(name)})
                      for name, raw in spec.conditions.items()]
        return ({c for g in spec.groups for c in g.controllers},
                {*spec.scenarios, spec.margin_scenario}, conditions)
    jobs = load_spec(path)
    return ({j.controller for j in jobs}, {j.scenario for j in jobs},
            list({j.condition.name: j.condition for j in jobs}.values()))


def test_there_are_studies():
    assert SPECS and PRESETS


@pytest.mark.parametrize("path", SPECS, ids=[str(p.relative_to(STUDIES)) for p in SPECS])
def test_a_study_spec_loads_and_what_it_names_resolves(path):
    controllers, scenarios, conditions = _named(path)
    for s in scenarios:
        assert not is_yaml_path(s) or Path(s).is_file(), s
        load_scenario(s)
    for c in controllers:
        assert not is_yaml_path(c) or Path(c).is_file(), c
        for cond in conditions:
            load_mpc_config(c, dict(cond.mpc_overrides))   # an unknown override key raises


def test_every_study_preset_is_named_by_a_spec():
    named = {Path(c) for p in SPECS for c in _named(p)[0] if is_yaml_path(c)}
    assert set(PRESETS) <= named, sorted(map(str, set(PRESETS) - named))
