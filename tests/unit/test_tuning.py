"""fourws tune: the one tuning procedure, its spec, its preset blocks, and that rerunning it
reproduces the shipped presets."""

from pathlib import Path

import numpy as np
import pytest

from fourws_bringup import tuning
from fourws_bringup.core.configs import load_mpc_config, node_values

ROOT = Path(__file__).resolve().parents[2]
SPEC = ROOT / "benchmarks" / "tuning.yaml"


def test_the_spec_is_disjoint_from_what_is_reported():
    """Nothing tuned on the paper's scenarios or the bench's: other scenarios, other seeds."""
    from fourws_bringup.sweep import load_spec

    spec = tuning.load_tuning_spec(SPEC)
    bench = load_spec(ROOT / "benchmarks" / "robustness.yaml") + \
        load_spec(ROOT / "benchmarks" / "limits.yaml")
    reported = {Path(j.scenario).stem for j in bench} | {"dlc_60_mu05", "dlc_90_mu06"}
    assert spec.grip_scenarios
    assert not {Path(s).stem for s in spec.scenarios + spec.grip_scenarios} & reported
    assert not set(spec.seeds) & {j.condition.seed for j in bench}
    members = [c for g in spec.groups for c in g.controllers]
    from fourws_bringup.core.configs import list_controllers

    assert sorted(members) == list_controllers()           # every preset, once


def test_candidates_start_from_the_package_defaults_on_one_grid_for_every_group():
    spec = tuning.load_tuning_spec(SPEC)
    sizes = {len(tuning.candidates(spec, g)) for g in spec.groups}
    assert sizes == {len(spec.grid_exponents) ** 2}          # the same budget
    for g in spec.groups:
        base = {p: float(node_values("mpc_node")[p]) for p in g.parameters}
        assert base in tuning.candidates(spec, g)             # exponent 0 is the default


def test_the_grip_scenarios_reach_beyond_the_limit():
    """Step 3's scenarios demand more than the road's grip (their printed demand in μg)."""
    from fourws_sim.core.scenario import load_scenario

    for path in tuning.load_tuning_spec(SPEC).grip_scenarios:
        assert 1.05 < load_scenario(path).demand_ratio < 1.15, path


def _fake_search(monkeypatch, table, radius=None, spins=()):
    """tune() on a 3 x 3 grid whose runs return ``table[grid index][run]`` (inf: an abort),
    whose candidates have ρ ``radius[grid index]`` (default 0.5) and whose grip run spins
    for the grid indices in ``spins``."""
    import dataclasses
    import math

    from fourws_bringup import sweep

    spec = dataclasses.replace(tuning.load_tuning_spec(SPEC), grid_exponents=(0, 1, 2),
                               groups=(tuning.Group("g", ("c",), ("p", "q")),))
    monkeypatch.setattr(tuning, "candidates",
                        lambda _s, _g: [{"p": float(i), "q": 0.0} for i in range(9)])
    monkeypatch.setattr(tuning, "_radius_job",
                        lambda a: (radius or [0.5] * 9)[int(a[2]["p"])])
    monkeypatch.setattr(tuning, "shipped", lambda _g: {"p": 4.0, "q": 0.0})
    monkeypatch.setattr(tuning, "_jobs", lambda _s, _g, c, grip=False: (
        [("grip", int(c["p"]))] if grip else [(int(c["p"]), r) for r in range(len(table[0]))]))
    ran = []

    def run_job(job):
        if job[0] == "grip":                 # spins: a set of indices, or index -> row
            return (spins[job[1]] if isinstance(spins, dict) and job[1] in spins else
                    {"controller": "c", "completed": True, "spin": job[1] in spins})
        ran.append(job)
        v = table[job[0]][job[1]]
        return {"controller": "c", "completed": math.isfinite(v),
                "max_abs_lateral_error_m": v}

    monkeypatch.setattr(sweep, "run_job", run_job)
    return spec, ran


def _brute_force(table, radius=None, spins=()):
    """The grid index step 5 chooses, from every run of every candidate."""
    import math

    radius = radius or [0.5] * 9
    kept = [g for g in range(9) if radius[g] <= 0.98 and g not in spins]
    score = {g: max(table[g]) for g in kept}
    ok = [g for g in kept if math.isfinite(score[g])
          and all(math.isfinite(score[h]) for h in tuning.neighbours(g, 3) if h in score)]
    return min(ok, key=lambda g: (score[g], radius[g], g))


def test_the_choice_sits_next_to_no_abort_and_equals_a_full_evaluation(monkeypatch):
    """Step 5: the best candidate (4) sits next to one (5) that aborts only in a run pruning
    skipped; the choice moves to the best whose kept neighbours complete, which is what
    a full evaluation of every run chooses, and the report marks the one set aside."""
    inf = float("inf")
    table = [[0.05, 0.05], [0.06, 0.06], [0.07, 0.07],
             [0.06, 0.06], [0.01, 0.01], [0.5, inf],
             [0.08, 0.08], [0.09, 0.09], [0.02, 0.02]]
    spec, ran = _fake_search(monkeypatch, table)
    chosen, report = tuning.tune(spec, progress=False)
    assert chosen["g"] == {"p": 0.0, "q": 0.0} and _brute_force(table) == 0
    assert (5, 1) in ran                                   # the pruned neighbour finished
    assert [r["p"] for r in report if r["set_aside"]] == [4.0, 8.0]
    assert len(ran) < 2 * 9                                # pruning still saves runs


def test_when_every_finished_candidate_is_set_aside_the_pruned_ones_are_finished(monkeypatch):
    """The best (4) sits next to two aborts (5, 7) that pruning had not run to the end, and
    every other candidate was pruned after one run: step 5 finishes them rather than give
    up, and takes the one whose kept neighbours complete (0: its neighbours 1 and 3 fail
    the margin and do not count)."""
    inf = float("inf")
    table = [[0.05, 0.05], [0.06, 0.06], [0.02, 0.02],
             [0.06, 0.06], [0.01, 0.01], [0.5, inf],
             [0.03, 0.03], [0.6, inf], [0.04, 0.04]]
    radius = [0.5, 0.99, 0.5, 0.99, 0.5, 0.5, 0.5, 0.5, 0.5]
    spec, _ = _fake_search(monkeypatch, table, radius)
    chosen, report = tuning.tune(spec, progress=False)
    assert chosen["g"]["p"] == 0.0 == float(_brute_force(table, radius))
    assert [r["p"] for r in report if r["set_aside"]] == [2.0, 4.0, 6.0, 8.0]


def test_a_candidate_that_spins_beyond_the_limit_is_not_kept(monkeypatch):
    """Step 3: the best tracker (4) spins on its grip run; it never runs the tracking
    scenarios, and although one of them would abort it does not count as its neighbours'
    neighbour: 5 is chosen, which step 5 would set aside if 4 counted. The report says who
    failed and why (a spin, an abort, a run that raised). When every candidate fails the
    group is an error naming the grip runs."""
    inf = float("inf")
    table = [[0.05, 0.05], [0.06, 0.06], [0.07, 0.07],
             [0.06, 0.06], [0.01, inf], [0.015, 0.015],
             [0.08, 0.08], [0.09, 0.09], [0.02, 0.02]]
    failing = {4: {"controller": "c", "completed": False, "spin": True},
               6: {"controller": "c", "completed": False, "spin": False, "reason": "road"},
               7: {"controller": "c", "completed": False, "reason": "raised ValueError: x"}}
    assert _brute_force(table) != 5                        # without step 3, 4 would count
    spec, ran = _fake_search(monkeypatch, table, spins=failing)
    chosen, report = tuning.tune(spec, progress=False)
    assert chosen["g"]["p"] == 5.0 == float(_brute_force(table, spins=set(failing)))
    assert not [job for job in ran if job[0] in failing]
    assert {r["p"]: r["grip"] for r in report if r["grip"] != "pass"} == {
        4.0: "fails: c (spins)", 6.0: "fails: c (aborts)", 7.0: "fails: c (raises)"}
    assert [r["p"] for r in report] == [float(g) for g in range(9)]     # grid order
    assert all(list(r)[:5] == ["group", "p", "q", "worst_rho", "grip"] for r in report)
    spec, _ = _fake_search(monkeypatch, table, spins=set(range(9)))
    with pytest.raises(ValueError, match="grip"):
        tuning.tune(spec, progress=False)


def test_the_grip_runs_are_the_grip_scenarios_under_the_grip_conditions_and_seeds():
    """Step 3's jobs: every controller of the group on every grip scenario, only under the
    grip conditions, every seed, with the candidate's values; a spec without ``grip`` (the
    studies' older specs) has no step 3."""
    spec = tuning.load_tuning_spec(SPEC)
    group = spec.groups[0]
    cand = tuning.candidates(spec, group)[5]
    jobs = tuning._jobs(spec, group, cand, grip=True)
    assert len(jobs) == (len(group.controllers) * len(spec.grip_conditions)
                         * len(spec.seeds) * len(spec.grip_scenarios))
    assert {j.scenario for j in jobs} == set(spec.grip_scenarios)
    assert {j.condition.name for j in jobs} == set(spec.grip_conditions)
    assert {j.controller for j in jobs} == set(group.controllers)
    assert all(j.condition.mpc_overrides.items() >= cand.items() for j in jobs)
    assert not {j.scenario for j in tuning._jobs(spec, group, cand)} & set(spec.grip_scenarios)
    old = tuning.load_tuning_spec(ROOT / "studies" / "horizon" / "tuning.yaml")
    assert old.grip_scenarios == () == old.grip_conditions


@pytest.mark.parametrize("seed", range(20))
def test_the_pruned_search_chooses_what_a_full_evaluation_chooses(monkeypatch, seed):
    """Random tables with aborts, margin-rejected candidates and candidates that spin
    beyond the limit: exact pruning plus step 5 choose the brute-force choice, or both find
    no candidate."""
    rng = np.random.default_rng(seed)
    table = rng.uniform(0.01, 0.1, (9, 3))
    table[rng.random((9, 3)) < 0.1] = np.inf
    radius = list(np.where(rng.random(9) < 0.15, 0.99, 0.5))
    spins = set(np.flatnonzero(rng.random(9) < 0.15).tolist())
    spec, _ = _fake_search(monkeypatch, table.tolist(), radius, spins)
    try:
        want = _brute_force(table.tolist(), radius, spins)
    except ValueError:                                     # min() of nothing
        with pytest.raises(ValueError, match="aborts|grip"):
            tuning.tune(spec, progress=False)
        return
    chosen, _ = tuning.tune(spec, progress=False)
    assert chosen["g"]["p"] == float(want)


def test_a_bad_spec_is_refused_naming_the_key(tmp_path):
    bad = tmp_path / "t.yaml"
    bad.write_text(SPEC.read_text(encoding="utf-8").replace("seeds:", "seedz:"),
                   encoding="utf-8")
    with pytest.raises(ValueError, match="seeds"):
        tuning.load_tuning_spec(bad)
    for params in ("[scale_y_m, no_such_parameter]", "[scale_y_m, scale_y_m]"):
        bad.write_text(SPEC.read_text(encoding="utf-8").replace(
            "[scale_y_m, scale_phi_deg]", params), encoding="utf-8")
        with pytest.raises(ValueError, match=params.split(", ")[1].rstrip("]")):
            tuning.load_tuning_spec(bad)
    bad.write_text(SPEC.read_text(encoding="utf-8").replace("speeds_kmh: [60.0, 90.0]",
                                                            "speeds_kmh: []"), encoding="utf-8")
    with pytest.raises(ValueError, match="speeds_kmh"):   # no loop: no candidate is checked
        tuning.load_tuning_spec(bad)
    text = SPEC.read_text(encoding="utf-8")
    # an empty list left nothing to run, and the procedure waited for ever
    for line, key in (("seeds: [100]", "seeds"), ("grid_exponents: [-8, -6, -4, -2, 0, 2, 4, 6]",
                                                  "grid_exponents")):
        assert line in text
        bad.write_text(text.replace(line, f"{key}: []"), encoding="utf-8")
        with pytest.raises(ValueError, match=key):
            tuning.load_tuning_spec(bad)
    scen = next(ln for ln in text.splitlines() if ln.startswith("scenarios:"))
    bad.write_text(text.replace(scen, "scenarios: []"), encoding="utf-8")
    with pytest.raises(ValueError, match="scenarios"):
        tuning.load_tuning_spec(bad)
    bad.write_text(text.replace("seeds: [100]", "seeds: [-3]"), encoding="utf-8")
    with pytest.raises(ValueError, match="seed"):
        tuning.load_tuning_spec(bad)
    bad.write_text(text.replace("realistic: {delay_periods: 1, steer_dead_time_ms: 40}",
                                "realistic: {delay_periods: 1, steer_dead_time_ms: -40}"),
                   encoding="utf-8")
    with pytest.raises(ValueError, match="steer_dead_time_ms"):
        tuning.load_tuning_spec(bad)
    grip = text[text.index("grip:\n"):text.index("groups:")]
    for wrong in (grip.replace("conditions: [all]", "conditions: [nosuch]"),
                  grip.replace("  conditions: [all]\n", ""),
                  grip.replace("  conditions: [all]\n", "  conditions: [all]\n  seeds: [1]\n"),
                  grip.replace("conditions: [all]", "conditions: all"),
                  "grip: [scenarios]\n"):
        bad.write_text(text.replace(grip, wrong), encoding="utf-8")
        with pytest.raises(ValueError, match="grip"):
            tuning.load_tuning_spec(bad)


def test_the_tuned_block_is_inserted_once_and_replaced_in_place():
    text = ("# a preset\nmpc_node:\n  ros__parameters:\n    controller: x\n"
            "allocator_node:\n  ros__parameters:\n    method: equal\n")
    once = tuning.replace_block(text, ["    scale_y_m: 0.01"])
    assert once.count(tuning.BEGIN) == 1 and "    scale_y_m: 0.01\n" in once
    assert once.index(tuning.END) < once.index("allocator_node")
    twice = tuning.replace_block(once, ["    scale_y_m: 0.02"])
    assert twice == once.replace("0.01", "0.02")
    with pytest.raises(ValueError, match="mpc_node"):
        tuning.replace_block("allocator_node: {}\n", [])


def test_a_preset_the_spec_gives_as_a_file_is_written_in_that_file(tmp_path):
    """A study's presets live beside its spec, not among the package's: the spec names the
    file (relative to itself), ``write_presets`` writes that file and no other."""
    shipped_np30 = ROOT / "src" / "fourws_bringup" / "config" / "controllers" / \
        "improved_np30.yaml"
    (tmp_path / "mine.yaml").write_text(shipped_np30.read_text(encoding="utf-8"),
                                        encoding="utf-8")
    text = SPEC.read_text(encoding="utf-8")
    text = text[:text.index("groups:")] + (
        "groups:\n  mine:\n    controllers: [mine.yaml]\n"
        "    parameters: [scale_y_m, scale_phi_deg]\n")
    (tmp_path / "tuning.yaml").write_text(text, encoding="utf-8")
    spec = tuning.load_tuning_spec(tmp_path / "tuning.yaml")
    assert spec.groups[0].controllers == (str(tmp_path / "mine.yaml"),)
    values = {"scale_y_m": 0.0118, "scale_phi_deg": 0.3}
    elsewhere = tmp_path / "package"
    elsewhere.mkdir()
    assert tuning.write_presets(spec, {"mine": values}, elsewhere, check=True) == \
        [str(tmp_path / "mine.yaml")]                      # differs, --check writes nothing
    assert tuning.write_presets(spec, {"mine": values}, elsewhere) == \
        [str(tmp_path / "mine.yaml")]
    cfg = load_mpc_config(str(tmp_path / "mine.yaml"))
    assert (cfg.scale_y_m, cfg.scale_phi_deg, cfg.np_baseline) == (0.0118, 0.3, 30)
    assert not list(elsewhere.iterdir())
    assert tuning.write_presets(spec, {"mine": values}, elsewhere, check=True) == []


@pytest.mark.parametrize("spec_path", [SPEC], ids=["shipped"])
def test_the_presets_carry_the_chosen_values_and_satisfy_the_margin(spec_path):
    """What the presets load is what their tuned block says, and the chosen candidate meets
    the procedure's own constraint (the full rerun of the shipped spec is the next test)."""
    spec = tuning.load_tuning_spec(spec_path)
    for g in spec.groups:
        vals = {}
        for c in g.controllers:
            cfg = load_mpc_config(c)
            vals[c] = tuple(getattr(cfg, p) for p in g.parameters)
        assert len(set(vals.values())) == 1, vals            # one common value per group
        chosen = dict(zip(g.parameters, next(iter(vals.values())), strict=True))
        assert chosen in tuning.candidates(spec, g)
        assert tuning.worst_radius(spec, g, chosen) <= spec.max_spectral_radius


#: the group CI reruns whole, through every step of the procedure (the cheapest runs: about
#: 10 s of the MPC groups' 1-3 min); ``make tune-check`` reruns every group
RERUN_GROUP = "lqr_ff"


@pytest.mark.slow
def test_rerunning_the_tuning_command_reproduces_the_shipped_presets(tmp_path, capsys):
    """``fourws tune benchmarks/tuning.yaml --check --group lqr_ff``: the whole procedure
    (margins, every kept candidate's closed-loop runs) on one representative group chooses
    exactly what its preset holds (``make tune-check`` runs every group)."""
    from fourws_bringup.cli import main

    report = tmp_path / "tuning.md"
    rc = main(["tune", str(SPEC), "--workers", "2", "--check", "--report", str(report),
               "--group", RERUN_GROUP])
    out = capsys.readouterr()
    assert rc == 0, out.err + out.out
    assert "the shipped presets are what the procedure chooses" in out.out
    text = report.read_text(encoding="utf-8")
    assert f"## {RERUN_GROUP}:" in text and "## mpc:" not in text


def test_an_unknown_group_is_refused_naming_it(capsys):
    from fourws_bringup.cli import main

    assert main(["tune", str(SPEC), "--check", "--group", "nosuch"]) == 2
    err = capsys.readouterr().err
    assert "nosuch" in err and "mpc_np30" in err
