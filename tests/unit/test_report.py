"""fourws_bringup.report: plotted quantities against closed-form cases, figure files, Markdown.

Oracle: a straight reference path along X, on which the lateral error of a pose is its Y
offset and the heading error its yaw, so every plotted error and metric is known exactly.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fourws_bringup.bag.errors import BagError
from fourws_bringup.bag.run_data import RunData
from fourws_bringup.core.configs import load_allocator_config
from fourws_bringup.core.metrics import (
    allocate_series,
    compute_metrics,
    rear_load_ratio_share,
    tyre_usage,
)
from fourws_bringup.report import (
    allocation_audit,
    draw_comparison,
    draw_figures,
    figures_markdown,
    metrics_table_markdown,
    series_of,
)
from fourws_bringup.scoring import tracking_metrics

DT = 0.01
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def make_run(n: int = 300, offset: float = 0.1, with_reference: bool = True,
             with_diagnostics: bool = True, name: str = "improved") -> RunData:
    k = np.arange(n)
    stamps = (k * 10_000_000).astype(np.int64)
    t = stamps * 1e-9
    y = offset * np.sin(2 * np.pi * t / 3.0)
    yaw = 0.05 * np.sin(2 * np.pi * t / 2.0)
    state = {"stamp_ns": stamps, "t_s": t, "x": 5.0 + 16.7 * t, "y": y, "yaw": yaw,
             "vx": np.full(n, 16.7), "vy": 0.1 * np.sin(t), "yaw_rate": np.gradient(yaw, DT),
             "ax": np.zeros(n), "ay": np.zeros(n), "sideslip": np.arctan2(0.1 * np.sin(t), 16.7),
             "steer_front": np.zeros(n), "steer_rear": np.zeros(n),
             "wheel_speed": np.ones((n, 4)), "wheel_torque": np.zeros((n, 4)),
             "fx": np.zeros((n, 4)), "fy": np.zeros((n, 4)), "fz": np.full((n, 4), 1800.0),
             "mu": np.full((n, 4), 0.5)}
    diag = {"stamp_ns": stamps[::2], "t_s": t[::2]}
    if with_diagnostics:
        m = len(diag["stamp_ns"])
        diag.update({"controller": np.array([name] * m, dtype=object),
                     "np": 12 + (np.arange(m) // 50) % 9, "nc": 6 + (np.arange(m) // 50) % 5,
                     "q_y": np.full(m, 4000.0), "q_phi": np.full(m, 2500.0),
                     "r_ddelta": np.full(m, 40000.0), "r_dmz": np.full(m, 30000.0),
                     "lateral_error": y[::2], "heading_error": yaw[::2],
                     "solve_time_ms": np.linspace(1.0, 3.0, m)})
    ref = None
    if with_reference:
        xs = np.linspace(0.0, 200.0, 401)
        ref = {"x": xs, "y": np.zeros_like(xs), "yaw": np.zeros_like(xs),
               "curvature": np.zeros_like(xs), "speed": np.full_like(xs, 16.7),
               "stamp_ns": np.int64(0)}
    cmd = {"stamp_ns": stamps, "t_s": t, "delta_front": np.zeros(n), "delta_rear": np.zeros(n),
           "yaw_moment": 100.0 * np.sin(t)}
    wt = {"stamp_ns": stamps, "t_s": t, "torque": np.tile([10.0, 11.0, 12.0, 13.0], (n, 1))}
    empty = {"stamp_ns": np.zeros(0, np.int64), "t_s": np.zeros(0)}
    return RunData(path=Path(f"/runs/{name}/bag/bag_0.mcap"), state=state, mpc_command=cmd,
                   mpc_diagnostics=diag, drive_command=empty, wheel_torques=wt,
                   reference=ref, status={"scenario": "straight", "completed": True},
                   message_counts={})


def test_plotted_errors_on_a_straight_path_are_the_offset_and_the_yaw():
    run = make_run()
    s = series_of(run)
    np.testing.assert_allclose(s.lateral_error, run.state["y"], atol=1e-12)
    np.testing.assert_allclose(s.heading_error, run.state["yaw"], atol=1e-12)
    np.testing.assert_allclose(s.ref_heading, 0.0, atol=1e-12)
    np.testing.assert_array_equal(s.torque[:, 3], 13.0)


def test_tracking_metrics_are_the_core_metrics_of_the_exact_errors():
    run = make_run()
    m = tracking_metrics(run)
    exact = compute_metrics(run.state["y"], run.state["yaw"], run.state["sideslip"],
                            run.mpc_diagnostics["solve_time_ms"])
    for key, v in exact.items():
        assert m[key] == pytest.approx(v, rel=1e-9, abs=1e-12), key
    assert m["max_abs_lateral_error_m"] == pytest.approx(0.1, rel=1e-3)
    assert m["steps"] == 300 and m["sim_time_s"] == pytest.approx(2.99)


def test_metrics_need_a_reference():
    with pytest.raises(BagError, match="reference"):
        tracking_metrics(make_run(with_reference=False))


def test_without_a_reference_the_mpc_diagnostics_errors_are_plotted_by_stamp():
    s = series_of(make_run(with_reference=False))
    np.testing.assert_allclose(s.lateral_error[::2], make_run().state["y"][::2])
    assert np.all(np.isnan(s.lateral_error[1::2]))
    assert s.ref_xy is None


def _is_png(p: Path) -> bool:
    import matplotlib.image as mpimg

    return p.read_bytes()[:8] == PNG_MAGIC and mpimg.imread(p).shape[0] > 100


def test_draw_figures_writes_every_figure_as_png(tmp_path):
    paths = draw_figures(make_run(), tmp_path / "plots")
    names = {p.name for p in paths}
    assert names == {"overview.png", "trajectory.png", "lateral_error.png",
                     "heading_error.png", "heading.png", "sideslip.png", "yaw_rate.png",
                     "horizons_weights.png", "wheel_torques.png"}
    assert all(p.parent == tmp_path / "plots" and _is_png(p) for p in paths)


def test_figures_drawn_by_two_processes_are_the_same_files(tmp_path):
    """``workers=2`` (``fourws run``) draws half of the figures in a forked process: the
    same paths in the same order and the same bytes as one process draws."""
    one = draw_figures(make_run(), tmp_path / "one")
    two = draw_figures(make_run(), tmp_path / "two", workers=2)
    assert [p.name for p in one] == [p.name for p in two]
    assert all(a.read_bytes() == b.read_bytes() for a, b in zip(one, two, strict=True))


def test_no_horizon_figure_without_diagnostics(tmp_path):
    paths = draw_figures(make_run(with_diagnostics=False), tmp_path)
    assert "horizons_weights.png" not in {p.name for p in paths}
    assert len(paths) == 8


def test_draw_comparison_overlays_runs(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    runs = {"MPC-4WS": make_run(offset=0.2, name="mpc_4ws"),
            "Improved MPC-4WS": make_run(offset=0.1)}
    paths = draw_comparison(runs, tmp_path, "DLC 60 km/h, mu 0.5")
    assert {p.name for p in paths} >= {"comparison_overview.png", "comparison_lateral_error.png",
                                       "comparison_horizons_weights.png",
                                       "comparison_wheel_torques.png"}
    assert all(_is_png(p) for p in paths)
    with pytest.raises(ValueError):
        draw_comparison({}, tmp_path, "none")


def test_empty_run_is_a_bag_error(tmp_path):
    run = make_run()
    run.state = {"stamp_ns": np.zeros(0, np.int64), "t_s": np.zeros(0)}
    with pytest.raises(BagError, match="no /vehicle/state"):
        draw_figures(run, tmp_path)


def test_markdown_helpers():
    table = metrics_table_markdown({"improved": {"a": 0.0891, "b": math.nan, "c": True}},
                                   ["a", "b", "c"], ["max eY m", "RMSE", "ok"])
    assert table.splitlines() == ["| run | max eY m | RMSE | ok |", "|---|---|---|---|",
                                  "| improved | 0.0891 | n/a | True |"]
    md = figures_markdown([Path("/r/x/plots/lateral_error.png")], "/r", heading="Figures")
    assert md == "### Figures\n\n![lateral error](x/plots/lateral_error.png)\n"


def test_missing_steps_counts_gaps_in_any_per_step_topic():
    from fourws_bringup.scoring import missing_steps

    run = make_run(n=200)
    assert missing_steps(run) == 99                  # make_run's diagnostics: every other step
    full = {"stamp_ns": run.state["stamp_ns"], "t_s": run.state["t_s"]}
    run = RunData(**{**run.__dict__, "mpc_diagnostics": full})
    assert missing_steps(run) == 0
    keep = np.ones(200, bool)
    keep[[50, 51, 120]] = False                      # a recorder that lost 3 commands
    cmd = {k: v[keep] for k, v in run.mpc_command.items()}
    assert missing_steps(RunData(**{**run.__dict__, "mpc_command": cmd})) == 3
    keep = np.ones(200, bool)
    keep[100:110] = False                            # ... or 10 states
    st = {k: v[keep] for k, v in run.state.items()}
    assert missing_steps(RunData(**{**run.__dict__, "state": st})) == 10


def test_rankings_group_ties_within_one_percent_and_aborted_runs_rank_last():
    from fourws_bringup.paper import TIE_REL, consistent, format_tables, rank, tie_groups

    m = {"a": {"completed": True, "max_abs_lateral_error_m": 0.978e-3},
         "b": {"completed": True, "max_abs_lateral_error_m": 0.952e-3},
         "c": {"completed": True, "max_abs_lateral_error_m": 0.953e-3},
         "d": {"completed": False, "max_abs_lateral_error_m": 0.5e-3, "sim_time_s": 5.0}}
    order = rank(m, "max_abs_lateral_error_m")
    assert order == ["b", "c", "a", "d"]                 # aborted last despite its small error
    groups = tie_groups(m, order, "max_abs_lateral_error_m")
    assert groups == [["b", "c"], ["a"], ["d"]]           # 0.1 % apart tie; 2.7 % do not
    assert TIE_REL == 0.01
    assert consistent(groups, ["c", "b", "a", "d"]) and consistent(groups, order)
    assert not consistent(groups, ["a", "b", "c", "d"]) and not consistent(groups, ["x"])
    keys = ("max_abs_lateral_error_m", "rmse_lateral_error_m", "mae_lateral_error_m",
            "max_abs_sideslip_deg", "rmse_sideslip_deg")
    res = {(c, "dlc_60_mu05"): {k: v for k in keys} | {"completed": True}
           for c, v in (("improved", 0.953e-3), ("ampc_4ws_dyc", 0.952e-3),
                        ("ampc_4ws", 0.978e-3))}
    text = format_tables(res)
    # a tie is not the paper's order: not contradicted, never "same" (issue 41, item 13)
    assert ("fourws ampc_4ws_dyc ≈ improved < ampc_4ws; paper improved < ampc_4ws_dyc < "
            "ampc_4ws (not contradicted (tie: ampc_4ws_dyc ≈ improved))") in text
    assert "(same" not in text and "Verdict rule" in text


def test_the_realistic_ranking_is_over_seeds_and_overlapping_spreads_tie():
    from fourws_bringup.paper import format_tables, range_groups, verdict

    vals = {"a": [0.050, 0.052, 0.060], "b": [0.055, 0.058, 0.059], "c": [0.070, 0.072, 0.08]}
    assert range_groups(vals) == [["a", "b"], ["c"]]          # a and b overlap; c is apart
    assert verdict([["a"], ["b"], ["c"]], ["a", "b", "c"]) == "same order"
    assert verdict([["a", "b"], ["c"]], ["b", "a", "c"]) == "not contradicted (tie: a ≈ b)"
    assert verdict([["a", "b"], ["c"]], ["c", "a", "b"]) == "DIFFERENT"
    keys = ("max_abs_lateral_error_m", "rmse_lateral_error_m", "mae_lateral_error_m",
            "max_abs_sideslip_deg", "rmse_sideslip_deg")

    def run(v, done=True):
        return {k: v for k in keys} | {"completed": done}

    seeds = {("improved", "dlc_60_mu05"): [run(0.060), run(0.058), run(0.062)],
             ("ampc_4ws_dyc", "dlc_60_mu05"): [run(0.059), run(0.061), run(0.063)],
             ("ampc_4ws", "dlc_60_mu05"): [run(0.080), run(0.090), run(0.010, False)]}
    res = {k: v[0] for k, v in seeds.items()}
    text = format_tables(res, "realistic", seeds)
    # medians 60 and 61 mm with overlapping spreads tie; ampc_4ws's aborted seed ranks it last
    assert ("fourws improved 60.0 (58.0–62.0) mm ≈ ampc_4ws_dyc 61.0 (59.0–63.0) mm < "
            "ampc_4ws 90.0 (80.0–inf) mm; paper improved < ampc_4ws_dyc < ampc_4ws "
            "(not contradicted (tie: improved ≈ ampc_4ws_dyc))") in text


def test_paper_exit_status_counts_broken_runs_not_aborted_ones():
    """An aborted run (the car left the corridor: a result) keeps `fourws paper` at exit 0;
    a dead node, missing metrics or steps missing from the bag make it fail, with the why."""
    from fourws_bringup.scoring import run_failure

    aborted = {"completed": False, "reason": "aborted: lateral error +5.02 m beyond ±5 m",
               "steps": 694, "missing_steps": 0}
    assert run_failure(aborted) is None
    assert run_failure({**aborted, "completed": True}) is None
    assert "mpc_node" in run_failure({**aborted, "died": "mpc_node"})
    assert "3 steps missing" in run_failure({**aborted, "missing_steps": 3})
    assert "metrics failed" in run_failure({"completed": False,
                                            "reason": "end; metrics failed: bad bag"})


def _allocation_run(method: str, n: int = 50) -> RunData:
    """make_run with drive commands and the wheel torques ``method`` gives on its inputs."""
    run = make_run(n)
    s = run.state
    k = np.arange(n)
    s["fz"] = np.column_stack([2400.0 - k, 1500.0 + k, 2100.0 - k, 1300.0 + k])
    s["fy"] = np.tile([-500.0, -400.0, -600.0, -450.0], (n, 1))
    s["fx"] = np.tile([150.0, -60.0, 120.0, -50.0], (n, 1))
    run.drive_command = {"stamp_ns": s["stamp_ns"], "t_s": s["t_s"],
                         "torque": np.linspace(0.0, 60.0, n)}
    cfg = load_allocator_config(None)
    torque = allocate_series(method, run.drive_command["torque"],
                             run.mpc_command["yaw_moment"], s["fz"], s["fy"], s["mu"], cfg)
    run.wheel_torques = {"stamp_ns": s["stamp_ns"], "t_s": s["t_s"], "torque": torque,
                         "allocation": np.array([method] * n, dtype=object)}
    return run


def test_rear_load_ratio_share_is_half_for_equal_loads_and_follows_mu_fz_squared():
    fz = np.array([[1800.0, 1800.0, 1800.0, 1800.0], [2000.0, 1000.0, 1000.0, 1000.0]])
    mu = np.array([[0.5] * 4, [0.5, 0.5, 0.5, 1.0]])
    share = rear_load_ratio_share(fz, mu)
    assert share[0] == pytest.approx([0.5, 0.5])
    assert share[1] == pytest.approx([1000.0**2 / (2000.0**2 + 1000.0**2), 4.0 / 5.0])
    assert np.isnan(rear_load_ratio_share(np.zeros((1, 4)), np.ones((1, 4)))).all()


def test_tyre_usage_is_eq_25():
    eta = tyre_usage(np.array([[300.0, 0, 0, 0]]), np.array([[400.0, 900.0, 0, 0]]),
                     np.full((1, 4), 1000.0), np.array([[1.0, 1.0, 0.5, 0.5]]))
    assert eta[0] == pytest.approx([0.5, 0.9, 0.0, 0.0])


def test_allocation_series_satisfies_eq_27_and_the_rule_splits_each_side_in_half():
    cfg = load_allocator_config(None)
    run = _allocation_run("optimal")
    s, t, mz = run.state, run.drive_command["torque"], run.mpc_command["yaw_moment"]
    for method in ("optimal", "rule"):
        w = allocate_series(method, t, mz, s["fz"], s["fy"], s["mu"], cfg)
        assert w.sum(axis=1) == pytest.approx(t)
        b_2r = cfg.track_width_m / (2.0 * cfg.wheel_radius_m)
        assert b_2r * (-w[:, 0] + w[:, 1] - w[:, 2] + w[:, 3]) == pytest.approx(mz)
    rule = allocate_series("rule", t, mz, s["fz"], s["fy"], s["mu"], cfg)
    assert rule[:, 0] == pytest.approx(rule[:, 2]) and rule[:, 1] == pytest.approx(rule[:, 3])


def test_allocation_audit_replays_the_recorded_method_and_compares_the_other():
    run = _allocation_run("optimal")
    audit = allocation_audit(run, other="rule")
    assert audit["method"] == "optimal" and audit["steps"] == 50
    assert audit["replay_error_nm"] == 0.0
    share = rear_load_ratio_share(run.state["fz"], run.state["mu"])
    assert audit["rear_share_min"] == pytest.approx(share.min())
    sums = run.wheel_torques["torque"][:, [0, 2]].sum(axis=1)
    # optimal differs from rule by |S_L| · |w_rear − 1/2| on the left (and likewise right)
    gap_left = np.abs(sums * (share[:, 0] - 0.5))
    assert audit["max_difference_nm"] >= gap_left.max() - 1e-9
    assert audit["max_tyre_usage"] == pytest.approx(
        tyre_usage(run.state["fx"], run.state["fy"], run.state["fz"], run.state["mu"]).max())
    run.wheel_torques["torque"] = run.wheel_torques["torque"] + 1.0
    assert allocation_audit(run)["replay_error_nm"] == pytest.approx(1.0)


def test_allocation_audit_names_the_missing_topic():
    run = make_run(20)  # no drive commands recorded
    with pytest.raises(BagError, match="drive_command"):
        allocation_audit(run)


def test_tables_6_and_7_carry_the_margins_of_their_controllers():
    from fourws_bringup.paper import format_tables

    text = format_tables({})
    lines = [ln for ln in text.splitlines() if ln.startswith("Linearised loop")]
    assert [ln.split(" km/h")[0] for ln in lines] == ["Linearised loop at 60",
                                                      "Linearised loop at 90"]
    for ln in lines:
        assert all(f"{c} ρ " in ln for c in ("mpc_fws", "mpc_4ws", "improved"))


def test_a_run_whose_node_died_ranks_last():
    """A died run's metrics carry no scores; ranking them raised KeyError after every run
    of ``fourws paper`` had finished, and report.md was never written."""
    from fourws_bringup.paper import rank

    m = {"a": {"completed": True, "max_abs_lateral_error_m": 0.2},
         "dead": {"completed": False, "reason": "mpc_node died", "sim_time_s": None},
         "b": {"completed": True, "max_abs_lateral_error_m": 0.1},
         "spun": {"completed": False, "sim_time_s": 4.0, "max_abs_lateral_error_m": 3.0}}
    assert rank(m, "max_abs_lateral_error_m") == ["b", "a", "spun", "dead"]


def test_paper_only_with_an_unknown_run_is_refused(tmp_path):
    from fourws_bringup.paper import run_paper

    with pytest.raises(ValueError, match="imporved@dlc_60_mu05"):
        run_paper(tmp_path / "out", only=["imporved@dlc_60_mu05"])
    assert not (tmp_path / "out").exists()          # refused before anything is made
