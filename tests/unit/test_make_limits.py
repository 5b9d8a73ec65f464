"""``tools/make_limits.py`` builds docs/limits.md from real sweep rows: a handful of runs is
enough to exercise every table and the printed rules (the full bench is ``make limits``)."""

from script_helpers import load_script


def test_the_page_is_built_from_a_few_rows_with_its_rules_and_tables(monkeypatch):
    from fourws_bringup.sweep import load_spec, run_job

    ml = load_script("tools/make_limits.py", monkeypatch)
    jobs = [j for j in load_spec(ml.SPEC)
            if j.condition.seed == 0 and ml.L.scenario_name(j.scenario) == "ladder_dlc_60_mu05_060"
            and (j.controller, j.condition.name) in {("improved", "ideal_friction"),
                                                     ("lqr_ff", "ideal")}]
    assert len(jobs) == 2
    text = ml.page([run_job(j) for j in jobs], ["phase_plane.png"])
    assert text.startswith("# Limit handling")
    for rule in ml.L.RULES:
        assert f"* {rule}" in text
    assert "## Headline: highest rung or speed passed clean" in text
    assert "| improved | ideal_shipped |" in text and "| lqr_ff | ideal_shipped |" in text
    adaptive = text.split("## What the adaptive parts did")[1].split("## Figures")[0]
    assert [ln for ln in adaptive.splitlines() if ln.startswith("### ")] == [
        "### DLC μ 0.5", "### DLC μ 0.9"]          # one table per lane-change ladder, named
    assert "![phase_plane.png](limits/phase_plane.png)" in text
    assert "## Runs that raised" not in text
