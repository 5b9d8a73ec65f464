"""Closed-form allocation methods (optimal, rule, equal) against generic oracles.

Oracle for ``optimal``: the KKT system of the paper's QP (eq. 26-27) solved by a dense
linear solve, min Σ T_i²/(r μ_i F_zi)² s.t. A T = b — no use of the side-split formula.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fourws_torque_alloc.core.allocation import (
    METHODS,
    AllocatorConfig,
    allocate,
    equal,
    optimal,
    rule,
    yaw_moment_nm,
)

CFG = AllocatorConfig()
# Motor limits out of the way: the equalities of eq. (27) are then exactly attainable.
CFG_UNLIMITED = AllocatorConfig(motor_torque_max_nm=1.0e5)
B, R = CFG.track_width_m, CFG.wheel_radius_m


def constraint_matrix(cfg: AllocatorConfig) -> np.ndarray:
    k = cfg.track_width_m / (2.0 * cfg.wheel_radius_m)
    return np.array([[1.0, 1.0, 1.0, 1.0], [-k, k, -k, k]])  # eq. (27)


def kkt_oracle(t: float, mz: float, fz: np.ndarray, mu: np.ndarray,
               cfg: AllocatorConfig) -> np.ndarray:
    p = np.diag(1.0 / (cfg.wheel_radius_m * mu * fz) ** 2)
    a = constraint_matrix(cfg)
    kkt = np.block([[2.0 * p, a.T], [a, np.zeros((2, 2))]])
    rhs = np.concatenate([np.zeros(4), [t, mz]])
    return np.linalg.solve(kkt, rhs)[:4]


loads = st.lists(st.floats(200.0, 6000.0), min_size=4, max_size=4).map(np.array)
mus = st.lists(st.floats(0.1, 1.2), min_size=4, max_size=4).map(np.array)
lat = st.lists(st.floats(-3000.0, 3000.0), min_size=4, max_size=4).map(np.array)
torque = st.floats(-2000.0, 2000.0)
moment = st.floats(-3000.0, 3000.0)


def _scale(t: float, mz: float) -> float:
    return max(1.0, abs(t), abs(mz) * 2.0 * R / B)


@settings(max_examples=300, deadline=None)
@given(torque, moment, loads, lat, mus)
def test_optimal_meets_equalities_and_matches_kkt(t, mz, fz, fy, mu):
    res = optimal(t, mz, fz, fy, mu, CFG_UNLIMITED)
    tq = res.torque_nm
    s = _scale(t, mz)
    assert abs(tq.sum() - t) <= 1e-9 * s
    assert abs(yaw_moment_nm(tq, CFG_UNLIMITED) - mz) <= 1e-9 * max(1.0, abs(mz), s * B / R)
    np.testing.assert_allclose(tq, kkt_oracle(t, mz, fz, mu, CFG_UNLIMITED), rtol=0,
                               atol=1e-6 * s)
    assert res.status == "ok"
    assert abs(res.unmet_torque_nm) <= 1e-9 * s
    assert abs(res.unmet_yaw_moment_nm) <= 1e-9 * s * B / R


@settings(max_examples=100, deadline=None)
@given(torque, moment, loads, mus)
def test_printed_eq28_31_are_not_the_optimum(t, mz, fz, mu):
    """As printed, eq. (28) puts T/2 − M_z r/B on both sides (so Σ T_i = T − 2 M_z r/B and
    no yaw moment), and eq. (31) halves each side whatever the loads. With the right-side
    sign fixed, the printed 1:1 split still costs more than the corrected optimum."""
    s_printed = t / 2 - mz * R / B
    t_rl = t_rr = s_printed / 2
    printed = np.array([s_printed - t_rl, s_printed - t_rr, t_rl, t_rr])
    assert math.isclose(printed.sum(), t - 2 * mz * R / B, rel_tol=1e-12, abs_tol=1e-9)
    assert abs(yaw_moment_nm(printed, CFG_UNLIMITED)) <= 1e-9 * _scale(t, mz)

    s_l, s_r = t / 2 - mz * R / B, t / 2 + mz * R / B
    sign_fixed = np.array([s_l / 2, s_r / 2, s_l / 2, s_r / 2])
    best = optimal(t, mz, fz, np.zeros(4), mu, CFG_UNLIMITED).torque_nm

    def cost(tq: np.ndarray) -> float:
        return float(np.sum((tq / (R * mu * fz)) ** 2))  # eq. (26)

    assert cost(best) <= cost(sign_fixed) * (1 + 1e-12) + 1e-15


def test_positive_yaw_moment_loads_the_right_wheels():
    fz = np.full(4, 1800.0)
    mu = np.full(4, 0.8)
    res = optimal(0.0, 500.0, fz, np.zeros(4), mu, CFG)
    assert res.torque_nm[1] > 0 > res.torque_nm[0]
    assert res.torque_nm[3] > 0 > res.torque_nm[2]


def test_split_follows_squared_capacity():
    fz = np.array([1000.0, 1000.0, 2000.0, 2000.0])
    mu = np.full(4, 0.5)
    res = optimal(600.0, 0.0, fz, np.zeros(4), mu, CFG)
    np.testing.assert_allclose(res.torque_nm, [60.0, 60.0, 240.0, 240.0], rtol=1e-12)


@settings(max_examples=200, deadline=None)
@given(torque, moment, loads, mus)
def test_rule_meets_equalities_and_splits_front_rear_equally(t, mz, fz, mu):
    res = rule(t, mz, fz, np.zeros(4), mu, CFG_UNLIMITED)
    tq = res.torque_nm
    s = _scale(t, mz)
    assert abs(tq.sum() - t) <= 1e-9 * s
    assert abs(yaw_moment_nm(tq, CFG_UNLIMITED) - mz) <= 1e-9 * s * B / R
    assert tq[0] == tq[2] and tq[1] == tq[3]
    assert math.isclose(tq[1] - tq[0], mz * R / B, rel_tol=1e-12, abs_tol=1e-9)


@settings(max_examples=200, deadline=None)
@given(torque, moment, loads, mus)
def test_rule_and_optimal_clip_to_motor_limits_and_report(t, mz, fz, mu):
    for fn in (rule, optimal):
        res = fn(t, mz, fz, np.zeros(4), mu, CFG)
        tq = res.torque_nm
        assert np.all(np.abs(tq) <= CFG.motor_torque_max_nm)
        assert math.isclose(res.unmet_torque_nm, t - tq.sum(), abs_tol=1e-9)
        assert math.isclose(res.unmet_yaw_moment_nm, mz - yaw_moment_nm(tq, CFG), abs_tol=1e-9)
        clipped = fn(t, mz, fz, np.zeros(4), mu, CFG_UNLIMITED).torque_nm
        np.testing.assert_allclose(tq, np.clip(clipped, -500.0, 500.0), atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(st.floats(-2000.0, 2000.0), moment, loads, mus)
def test_equal_sums_to_t(t, mz, fz, mu):
    res = equal(t, mz, fz, np.zeros(4), mu, CFG)
    assert math.isclose(res.torque_nm.sum(), t, abs_tol=1e-9)
    assert np.all(res.torque_nm == res.torque_nm[0])
    assert math.isclose(res.unmet_yaw_moment_nm, mz, abs_tol=1e-9)


wheel_fz = st.one_of(st.floats(-500.0, 0.0), st.floats(0.0, 150.0), st.floats(150.0, 6000.0))


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(METHODS), torque, moment,
       st.lists(wheel_fz, min_size=4, max_size=4).map(np.array), lat,
       st.lists(st.floats(0.0, 1.2), min_size=4, max_size=4).map(np.array))
def test_wheel_in_the_air_gives_finite_output(method, t, mz, fz, fy, mu):
    res = allocate(method, t, mz, fz, fy, mu, CFG)
    assert res.torque_nm.shape == (4,)
    assert np.all(np.isfinite(res.torque_nm))
    assert math.isfinite(res.unmet_torque_nm) and math.isfinite(res.unmet_yaw_moment_nm)
    assert np.all(np.abs(res.torque_nm) <= CFG.motor_torque_max_nm + 1e-9)


def test_optimal_one_wheel_in_air_partner_takes_the_side():
    fz = np.array([0.0, 1800.0, 1900.0, 1700.0])  # FL in the air
    mu = np.full(4, 0.7)
    res = optimal(400.0, 300.0, fz, np.zeros(4), mu, CFG)
    s_left = 200.0 - 300.0 * R / B
    assert res.torque_nm[0] == 0.0
    assert math.isclose(res.torque_nm[2], s_left, rel_tol=1e-12)
    assert "wheel_lift" in res.status and "limited" not in res.status


def test_optimal_side_in_air_reports_unmet():
    fz = np.array([-50.0, 1800.0, 20.0, 1700.0])  # whole left side in the air
    mu = np.full(4, 0.7)
    t, mz = 400.0, 300.0
    res = optimal(t, mz, fz, np.zeros(4), mu, CFG)
    s_left = t / 2 - mz * R / B
    assert res.torque_nm[0] == 0.0 and res.torque_nm[2] == 0.0
    assert math.isclose(res.unmet_torque_nm, s_left, rel_tol=1e-12)
    assert math.isclose(res.unmet_yaw_moment_nm, -s_left * B / (2 * R), rel_tol=1e-12)
    assert "limited" in res.status and "wheel_lift" in res.status


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize(
    ("t", "mz", "fz", "match"),
    [
        (math.nan, 0.0, [1800.0] * 4, "total torque"),
        (0.0, math.inf, [1800.0] * 4, "yaw moment"),
        (0.0, 0.0, [1800.0, math.nan, 1800.0, 1800.0], "fz"),
        (0.0, 0.0, [1800.0] * 3, "shape"),
        (1.0e6, 0.0, [1800.0] * 4, "sanity limit"),
        (0.0, -1.0e6, [1800.0] * 4, "sanity limit"),
    ],
)
def test_bad_inputs_raise(method, t, mz, fz, match):
    with pytest.raises(ValueError, match=match):
        allocate(method, t, mz, np.array(fz), np.zeros(len(fz)), np.full(len(fz), 0.8), CFG)


def test_bad_mu_raises_and_unknown_method():
    fz = np.full(4, 1800.0)
    with pytest.raises(ValueError, match="mu"):
        optimal(0.0, 0.0, fz, np.zeros(4), np.array([0.8, -0.1, 0.8, 0.8]), CFG)
    with pytest.raises(ValueError, match="method"):
        allocate("magic", 0.0, 0.0, fz, np.zeros(4), np.full(4, 0.8), CFG)


def test_result_is_read_only():
    res = optimal(100.0, 0.0, np.full(4, 1800.0), np.zeros(4), np.full(4, 0.8), CFG)
    with pytest.raises(ValueError):
        res.torque_nm[0] = 1.0
