"""The limit bench's metrics (``core.limit_metrics``) and report rules (``limits_report``)
on constructed runs, and the ISO 3888-2 course they are checked on."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from fourws_bringup import limits_report as L
from fourws_bringup.core.limit_metrics import (
    LANE_FREE_M,
    SPIN_SIDESLIP_DEG,
    braking_distance,
    cone_excess,
    delivered_yaw_moment,
    limit_metrics,
)
from fourws_mpc.core.reference import Reference
from fourws_sim.core.paths import iso3888_2, iso3888_2_lanes, peak_lateral_accel_demand

B, R = 1.3, 0.27


def _log(y, beta_deg, vx=16.0, mu=0.5, reason="end of scenario", lanes=(), mz=None,
         wheels=None, drive=None, completed=True):
    n = len(y)
    x = np.linspace(0.0, vx * 0.01 * (n - 1), n)
    xs = np.linspace(-20.0, 400.0, 8401)
    ref = Reference.from_arrays(xs, np.zeros_like(xs), np.zeros_like(xs),
                                np.full_like(xs, 0.01), np.full_like(xs, vx))
    state = {"x": x, "y": np.asarray(y, float), "yaw": np.zeros(n), "vx": np.full(n, vx),
             "sideslip": np.radians(np.asarray(beta_deg, float)),
             "yaw_rate": np.full(n, 0.1), "mu": np.full((n, 4), mu)}
    return SimpleNamespace(
        state=state, reference=ref, reason=reason, completed=completed, lanes=lanes,
        mpc={"yaw_moment": np.zeros(n) if mz is None else np.asarray(mz, float)},
        wheel_torque_cmd_nm=np.zeros((n, 4)) if wheels is None else np.asarray(wheels),
        drive_torque_nm=np.zeros(n) if drive is None else np.asarray(drive, float))


def test_a_clean_run_and_its_demand():
    m = limit_metrics(_log(np.zeros(50), np.full(50, 2.0)), B, R)
    assert not m["spin"] and not m["lane_violation"] and m["completed_clean"]
    assert m["demand_mug"] == pytest.approx(0.01 * 16.0 ** 2 / (0.5 * 9.81), rel=1e-9)
    assert m["yaw_rate_ratio"] == pytest.approx(0.1 / (0.5 * 9.81 / 16.0), rel=1e-9)


def test_spin_is_a_sideslip_of_ten_degrees_or_an_abort_on_it():
    beta = np.zeros(50)
    beta[20] = SPIN_SIDESLIP_DEG
    assert limit_metrics(_log(np.zeros(50), beta), B, R)["spin"]
    beta[20] = SPIN_SIDESLIP_DEG - 0.1
    m = limit_metrics(_log(np.zeros(50), beta), B, R)
    assert not m["spin"]
    m = limit_metrics(_log(np.zeros(50), np.zeros(50),
                           reason="aborted: sideslip +30.1° beyond ±30°"), B, R)
    assert m["spin"] and not m["completed_clean"]


def test_the_lane_rule_off_a_cone_course():
    y = np.zeros(50)
    y[10] = LANE_FREE_M + 0.01
    assert limit_metrics(_log(y, np.zeros(50)), B, R)["lane_violation"]
    y[10] = LANE_FREE_M - 0.01
    assert not limit_metrics(_log(y, np.zeros(50)), B, R)["lane_violation"]


def test_the_cones_see_the_body_width_around_the_cg():
    lanes = ((0.0, 10.0, 0.0, 2.0),)
    x = np.array([5.0])
    # half-width 0.75, so the CG may sit 0.25 m off the lane's centre
    assert cone_excess(lanes, x, np.array([0.25])) == pytest.approx(0.0)
    assert cone_excess(lanes, x, np.array([-0.35])) == pytest.approx(0.1)
    assert cone_excess(lanes, np.array([12.0]), np.array([3.0])) == 0.0    # past the lane


def test_unmet_yaw_moment_and_drive_force_are_demand_less_delivery():
    wheels = np.array([[-100.0, 100.0, -100.0, 100.0]] * 5)     # 2 B/(2R)·200 N·m of M_z
    mz_delivered = delivered_yaw_moment(wheels, B, R)
    np.testing.assert_allclose(mz_delivered, B / (2 * R) * 400.0)
    m = limit_metrics(_log(np.zeros(5), np.zeros(5), mz=mz_delivered + 50.0, wheels=wheels,
                           drive=np.full(5, 27.0)), B, R)
    assert m["unmet_mz_max_nm"] == pytest.approx(50.0)
    assert m["unmet_fx_max_n"] == pytest.approx(27.0 / R)


def test_braking_distance_from_the_reference_drop_to_the_final_speed():
    x = np.linspace(0.0, 100.0, 101)
    v_ref = np.where(x < 20.0, 20.0, np.maximum(20.0 - 0.25 * (x - 20.0), 6.0))
    vx = np.where(x < 30.0, 20.0, np.maximum(20.0 - 0.25 * (x - 30.0), 6.0))
    # the reference drops below 19.9 m/s at X = 21 m; the car reaches 6.5 m/s at X = 84 m
    assert braking_distance(x, vx, v_ref) == pytest.approx(84.0 - 21.0)
    assert math.isnan(braking_distance(x, vx, np.full_like(x, 20.0)))


def test_the_iso3888_2_course_has_the_standards_lanes_and_its_centre_line_fits_them():
    w = 1.5
    lanes = iso3888_2_lanes(w)
    (e0, e1, ey, ew), (s0, s1, sy, sw), (x0, x1, xy, xw) = lanes
    assert (e1 - e0, s0 - e1, s1 - s0, x0 - s1, x1 - x0) == pytest.approx(
        (12.0, 13.5, 11.0, 12.5, 12.0))
    assert (ew, sw, xw) == pytest.approx((1.1 * w + 0.25, w + 1.0, 3.0))
    assert (sy - sw / 2) - (ey + ew / 2) == pytest.approx(1.0)     # 1 m beyond the entry lane
    assert xy - xw / 2 == pytest.approx(ey - ew / 2)               # exit's right edge
    for margin in (0.0, 0.1):
        p = iso3888_2(50 / 3.6, w, cone_margin_m=margin)
        assert p.lanes == tuple(lanes)
        # followed exactly, the centre line keeps the body the margin inside the cones
        assert cone_excess(p.lanes, p.x, p.y) <= 1e-6
        for a, b, yc, width in lanes:
            inside = (p.x >= a) & (p.x <= b)
            assert np.max(np.abs(p.y[inside] - yc)) + w / 2 <= width / 2 - margin + 1e-6
    # 50 km/h: about 1 μg on μ 0.9; the margin makes it steeper
    assert peak_lateral_accel_demand(iso3888_2(50 / 3.6, w)) > 0.9 * 9.81 * 0.9
    assert peak_lateral_accel_demand(iso3888_2(50 / 3.6, w, cone_margin_m=0.1)) > \
        peak_lateral_accel_demand(iso3888_2(50 / 3.6, w))


def _row(c, sc, cond, seed, clean, beta=2.0):
    return {"controller": c, "scenario": f"limits/{sc}.yaml", "condition": cond,
            "seed": seed, "completed_clean": clean, "spin": not clean,
            "max_abs_sideslip_deg": beta, "max_abs_lateral_error_m": 0.1}


def test_the_headline_is_the_highest_clean_rung_below_any_failure():
    rows = [_row("improved", "ladder_dlc_60_mu05_060", "r", s, True) for s in range(2)]
    rows += [_row("improved", "ladder_dlc_60_mu05_090", "r", 0, True),
             _row("improved", "ladder_dlc_60_mu05_090", "r", 1, False),
             _row("improved", "ladder_dlc_60_mu05_110", "r", 0, True),
             _row("improved", "ladder_dlc_60_mu05_110", "r", 1, True)]
    best, failed = L.headline(L.cases(rows), "improved", "r", "ladder_dlc_60_mu05_")
    assert best == 0.6 and failed == [0.9]


def test_paired_change_and_twin_failures():
    rows = [_row("improved", "ladder_dlc_60_mu05_110", "r", s, True, beta=3.0)
            for s in range(3)]
    rows += [_row("ampc_4ws", "ladder_dlc_60_mu05_110", "r", s, True, beta=4.0)
             for s in range(3)]
    rows += [_row("improved", "ladder_dlc_60_mu05_060", "r", 0, False),
             _row("ampc_4ws", "ladder_dlc_60_mu05_060", "r", 0, True)]
    by = L.cases(rows)
    assert L.paired_change(by, "improved", "ampc_4ws", "r",
                           "max_abs_sideslip_deg") == pytest.approx([-0.25] * 3)
    assert L.twin_failures(by) == ["improved fails ladder_dlc_60_mu05_060 (r) where "
                                   "ampc_4ws completes"]


def test_the_shipped_view_takes_each_preset_under_its_own_model():
    rows = [_row("improved", "ladder_dlc_60_mu05_110", cd, 0, cd.endswith("friction"))
            for cd in ("realistic_friction", "realistic_linear")]
    rows += [_row("mpc_4ws", "ladder_dlc_60_mu05_110", cd, 0, cd.endswith("linear"))
             for cd in ("realistic_friction", "realistic_linear")]
    rows += [_row("lqr_ff", "ladder_dlc_60_mu05_110", "realistic", 0, True)]
    by = L.with_shipped(L.cases(rows), {"improved": "friction", "mpc_4ws": "linear"})
    for c in ("improved", "mpc_4ws", "lqr_ff"):
        assert L.clean(by[(c, "ladder_dlc_60_mu05_110", "realistic_shipped")]), c


def test_a_runs_nearest_points_are_computed_once_and_give_the_same_metrics():
    """A closed-loop log's ``nearest`` is ``metrics.path_nearest`` of its true poses, and the
    metrics and limit metrics that take it equal those that compute it again."""
    from fourws_bringup.core.closed_loop import run_closed_loop
    from fourws_bringup.core.metrics import path_nearest, run_metrics

    log = run_closed_loop("dlc_60_mu05", "improved", max_steps=300)
    s = log.state
    again = path_nearest(log.reference, s["x"], s["y"], s["yaw"])
    assert all(np.array_equal(a, b) for a, b in zip(log.nearest, again, strict=True))
    assert log.nearest is log.nearest                       # cached
    plain = run_metrics(log.reference, s["t_s"], s["x"], s["y"], s["yaw"], s["vx"], s["vy"],
                        s["sideslip"], log.solve_ms)
    assert {k: log.metrics()[k] for k in plain} == plain
    assert limit_metrics(log, B, R, nearest=log.nearest) == limit_metrics(log, B, R)


def test_a_wider_car_is_checked_at_its_own_width():
    """The cones and the lane rule take the course's car width (its scenario's
    ``vehicle_width_m``), not a fixed 1.5 m: a wider course's car reaching the same offset
    hits a cone the 1.5 m body would not."""
    from fourws_bringup.core.limit_metrics import lane_free_m

    lanes = ((0.0, 10.0, 0.0, 2.5),)
    x, y = np.linspace(0.0, 9.0, 10), np.full(10, 0.4)
    assert cone_excess(lanes, x, y) == 0.0                          # 0.4 + 0.75 < 1.25
    assert cone_excess(lanes, x, y, 1.8) == pytest.approx(0.05)     # 0.4 + 0.9 − 1.25
    assert lane_free_m(1.5) == pytest.approx(LANE_FREE_M) == pytest.approx(0.275)
    y = np.zeros(50)
    y[10] = 0.29                                  # beyond 1.5 m's 0.275, within 1.8 m's 0.305
    wide = _log(y, np.zeros(50))
    assert limit_metrics(wide, B, R)["lane_violation"]
    wide.vehicle_width_m = 1.8
    assert not limit_metrics(wide, B, R)["lane_violation"]
    course = iso3888_2(speed_mps=10.0, vehicle_width_m=1.8)
    assert course.vehicle_width_m == 1.8 and course.lanes == tuple(iso3888_2_lanes(1.8))


def test_a_run_that_ended_at_once_keeps_its_reason():
    """A run aborted before its first step raised in the metrics (a reshape of nothing), and
    the sweep's row said 'raised' instead of the abort."""
    log = _log(np.zeros(0), np.zeros(0), reason="aborted: lateral error 5.0 m")
    log.state["mu"] = np.zeros((0, 4))
    m = limit_metrics(log, B, R)
    assert m["lane_violation"] and not m["completed_clean"] and not m["spin"]
    assert math.isnan(m["demand_mug"]) and math.isnan(m["braking_distance_m"])
