"""``optimal_bounded`` against generic oracles.

- Bounds are recomputed here from their definition (motor limit, friction circle).
- The lexicographic priority is checked with linear programs (scipy HiGHS): the achievable
  range of the prioritised quantity over the box, then of the other one with the first held.
- The final split is checked against an active-set enumeration of the QP (every wheel free,
  at +b or at −b; the equality-constrained KKT system solved on each face; the cheapest
  feasible candidate is the optimum) — a generic QP method, not the per-side formula.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog

from fourws_torque_alloc.core.allocation import (
    PRIORITIES,
    AllocatorConfig,
    BoundedQp,
    optimal,
    optimal_bounded,
    wheel_bounds_nm,
    yaw_moment_nm,
)

CFG = AllocatorConfig(method="optimal_bounded")
B, R, TMAX = CFG.track_width_m, CFG.wheel_radius_m, CFG.motor_torque_max_nm
K = B / (2.0 * R)
A_T = np.ones(4)
A_M = K * np.array([-1.0, 1.0, -1.0, 1.0])
SOLVERS = ("osqp", "analytic")


def cfg_for(priority: str, solver: str) -> AllocatorConfig:
    return AllocatorConfig(method="optimal_bounded", priority=priority, bounded_solver=solver)


def bounds_oracle(fz, fy, mu, cfg=CFG) -> np.ndarray:
    out = np.zeros(4)
    for i in range(4):
        if fz[i] > cfg.min_fz_n and mu[i] * fz[i] > 1e-3:
            out[i] = min(cfg.motor_torque_max_nm,
                         cfg.wheel_radius_m * math.sqrt(max((mu[i] * fz[i]) ** 2 - fy[i] ** 2,
                                                            0.0)))
    return out


def lp_range(c: np.ndarray, b: np.ndarray, a_eq=None, b_eq=None) -> tuple[float, float]:
    kw = {"bounds": list(zip(-b, b, strict=True)), "method": "highs"}
    if a_eq is not None:
        kw.update(A_eq=a_eq[None, :], b_eq=[b_eq])
    lo = linprog(c, **kw)
    hi = linprog(-c, **kw)
    assert lo.status == 0 and hi.status == 0
    return float(lo.fun), float(-hi.fun)


def priority_oracle(t, mz, b, priority):
    a_p, d_p, a_s, d_s = (A_M, mz, A_T, t) if priority == "yaw_moment" else (A_T, t, A_M, mz)
    lo, hi = lp_range(a_p, b)
    p_star = min(max(d_p, lo), hi)
    lo2, hi2 = lp_range(a_s, b, a_p, p_star)
    s_star = min(max(d_s, lo2), hi2)
    return (s_star, p_star) if priority == "yaw_moment" else (p_star, s_star)


def enumeration_oracle(t_star, mz_star, b, cap) -> np.ndarray:
    p = np.where(cap > 0, 1.0 / np.where(cap > 0, R * cap, 1.0) ** 2, 1.0)
    a = np.vstack([A_T, A_M])
    rhs = np.array([t_star, mz_star])
    tol = 1e-9 * max(1.0, abs(t_star), abs(mz_star), TMAX)
    best, best_cost = None, math.inf
    choices = [(0,) if b[i] == 0.0 else (0, 1, -1) for i in range(4)]  # 0 = free
    for state in itertools.product(*choices):
        x = np.array([s * b[i] for i, s in enumerate(state)], dtype=float)
        free = [i for i in range(4) if state[i] == 0 and b[i] > 0.0]
        r = rhs - a @ x
        if free:
            af = a[:, free]
            n = len(free)
            kkt = np.block([[2 * np.diag(p[free]), af.T], [af, np.zeros((2, 2))]])
            sol = np.linalg.lstsq(kkt, np.concatenate([np.zeros(n), r]), rcond=None)[0]
            x[free] = sol[:n]
        if np.max(np.abs(a @ x - rhs)) > tol or np.any(np.abs(x) > b + tol):
            continue
        cost = float(np.sum(p * x * x))
        if cost < best_cost:
            best, best_cost = x, cost
    assert best is not None
    return best


def capacity(fz, mu):
    return np.where((fz > CFG.min_fz_n) & (mu * fz > 1e-3), mu * fz, 0.0)


vec = st.lists(st.floats(0.0, 1.0), min_size=4, max_size=4).map(np.array)
wheel_fz = st.one_of(st.floats(-300.0, 150.0), st.floats(150.0, 5000.0),
                     st.floats(150.0, 5000.0), st.floats(150.0, 5000.0))
fzs = st.lists(wheel_fz, min_size=4, max_size=4).map(np.array)
mus = st.lists(st.floats(0.05, 1.2), min_size=4, max_size=4).map(np.array)


@settings(max_examples=250, deadline=None)
@given(st.floats(-3000.0, 3000.0), st.floats(-6000.0, 6000.0), fzs, vec, mus,
       st.sampled_from(PRIORITIES), st.sampled_from(SOLVERS))
def test_bounds_never_exceeded(t, mz, fz, fy_frac, mu, priority, solver):
    fy = (2 * fy_frac - 1) * 1.2 * mu * np.abs(fz)
    res = optimal_bounded(t, mz, fz, fy, mu, cfg_for(priority, solver))
    tq = res.torque_nm
    b = bounds_oracle(fz, fy, mu)
    np.testing.assert_allclose(wheel_bounds_nm(fz, fy, mu, CFG), b, rtol=1e-12, atol=1e-12)
    assert np.all(np.abs(tq) <= TMAX)
    assert np.all(np.abs(tq) <= b * (1 + 1e-12) + 1e-12)
    grip = np.where(capacity(fz, mu) > 0, (mu * fz) ** 2, 0.0)
    assert np.all((tq / R) ** 2 <= np.maximum(grip - fy**2, 0.0) * (1 + 1e-9) + 1e-9)
    assert math.isclose(res.unmet_torque_nm, t - tq.sum(), abs_tol=1e-9)
    assert math.isclose(res.unmet_yaw_moment_nm, mz - yaw_moment_nm(tq, CFG), abs_tol=1e-9)


@settings(max_examples=250, deadline=None)
@given(st.floats(-3000.0, 3000.0), st.floats(-6000.0, 6000.0), fzs, vec, mus,
       st.sampled_from(PRIORITIES), st.sampled_from(SOLVERS))
def test_priority_and_split_match_generic_oracles(t, mz, fz, fy_frac, mu, priority, solver):
    fy = (2 * fy_frac - 1) * 1.2 * mu * np.abs(fz)
    b = bounds_oracle(fz, fy, mu)
    res = optimal_bounded(t, mz, fz, fy, mu, cfg_for(priority, solver))
    t_star, mz_star = priority_oracle(t, mz, b, priority)
    scale = max(1.0, abs(t), abs(mz) / K, TMAX)
    assert math.isclose(res.unmet_torque_nm, t - t_star, abs_tol=1e-6 * scale)
    assert math.isclose(res.unmet_yaw_moment_nm, mz - mz_star, abs_tol=1e-6 * scale * K)
    expected = enumeration_oracle(t_star, mz_star, b, capacity(fz, mu))
    np.testing.assert_allclose(res.torque_nm, expected, rtol=0, atol=1e-6 * scale)


@settings(max_examples=250, deadline=None)
@given(st.floats(-3000.0, 3000.0), st.floats(-6000.0, 6000.0), fzs, vec, mus,
       st.sampled_from(SOLVERS))
def test_prioritised_quantity_met_exactly_when_attainable(t, mz, fz, fy_frac, mu, solver):
    fy = (2 * fy_frac - 1) * 1.2 * mu * np.abs(fz)
    b = bounds_oracle(fz, fy, mu)
    scale = max(1.0, abs(t), abs(mz) / K, TMAX)
    # yaw moment first: attainable iff |2 r Mz / B| ≤ Σ b_i
    res = optimal_bounded(t, mz, fz, fy, mu, cfg_for("yaw_moment", solver))
    if abs(mz) / K <= b.sum() * (1 - 1e-9):
        assert abs(res.unmet_yaw_moment_nm) <= 1e-9 * scale * K
        lo, hi = lp_range(A_T, b, A_M, mz)
        t_best = min(max(t, lo), hi)
        assert math.isclose(res.unmet_torque_nm, t - t_best, abs_tol=1e-6 * scale)
    # total torque first: attainable iff |T| ≤ Σ b_i
    res = optimal_bounded(t, mz, fz, fy, mu, cfg_for("total_torque", solver))
    if abs(t) <= b.sum() * (1 - 1e-9):
        assert abs(res.unmet_torque_nm) <= 1e-9 * scale
        lo, hi = lp_range(A_M, b, A_T, t)
        m_best = min(max(mz, lo), hi)
        assert math.isclose(res.unmet_yaw_moment_nm, mz - m_best, abs_tol=1e-6 * scale * K)


@settings(max_examples=200, deadline=None)
@given(st.floats(-800.0, 800.0), st.floats(-800.0, 800.0),
       st.lists(st.floats(1500.0, 5000.0), min_size=4, max_size=4).map(np.array),
       vec, st.lists(st.floats(0.6, 1.2), min_size=4, max_size=4).map(np.array),
       st.sampled_from(PRIORITIES), st.sampled_from(SOLVERS))
def test_equals_optimal_when_no_bound_is_active(t, mz, fz, fy_frac, mu, priority, solver):
    fy = (2 * fy_frac - 1) * 0.4 * mu * fz
    ref = optimal(t, mz, fz, fy, mu, CFG)
    b = bounds_oracle(fz, fy, mu)
    assume(np.all(np.abs(ref.torque_nm) < b * (1 - 1e-6)))
    res = optimal_bounded(t, mz, fz, fy, mu, cfg_for(priority, solver))
    scale = max(1.0, abs(t), abs(mz) / K)
    np.testing.assert_allclose(res.torque_nm, ref.torque_nm, rtol=0, atol=1e-9 * scale)
    assert res.status in ("ok", "solver_fallback")  # the fallback is exact too


def test_workspace_history_does_not_change_the_result():
    rng = np.random.default_rng(7)
    shared = BoundedQp()
    cfg = cfg_for("yaw_moment", "osqp")
    for _ in range(200):
        fz = rng.uniform(200.0, 4000.0, 4)
        mu = rng.uniform(0.2, 1.0, 4)
        fy = rng.uniform(-0.8, 0.8, 4) * mu * fz
        t, mz = rng.uniform(-2500, 2500), rng.uniform(-4000, 4000)
        a = optimal_bounded(t, mz, fz, fy, mu, cfg, shared)
        b = optimal_bounded(t, mz, fz, fy, mu, cfg, BoundedQp())
        np.testing.assert_allclose(a.torque_nm, b.torque_nm, rtol=0, atol=1e-9)


@pytest.mark.parametrize("solver", SOLVERS)
def test_side_in_the_air_priorities(solver):
    fz = np.array([0.0, 1800.0, -20.0, 1800.0])  # left side in the air
    mu = np.full(4, 0.8)
    fy = np.zeros(4)
    yaw_first = optimal_bounded(400.0, 0.0, fz, fy, mu, cfg_for("yaw_moment", solver))
    np.testing.assert_array_equal(yaw_first.torque_nm, np.zeros(4))
    assert yaw_first.unmet_torque_nm == pytest.approx(400.0)
    assert "wheel_lift" in yaw_first.status and "limited" in yaw_first.status
    torque_first = optimal_bounded(400.0, 0.0, fz, fy, mu, cfg_for("total_torque", solver))
    np.testing.assert_allclose(torque_first.torque_nm, [0.0, 200.0, 0.0, 200.0], atol=1e-9)
    assert torque_first.unmet_torque_nm == pytest.approx(0.0, abs=1e-9)
    assert torque_first.unmet_yaw_moment_nm == pytest.approx(-400.0 * K)


def test_friction_circle_can_be_switched_off():
    fz = np.full(4, 1800.0)
    mu = np.full(4, 0.5)
    fy = np.full(4, 900.0)  # lateral force uses all the grip
    on = optimal_bounded(400.0, 0.0, fz, fy, mu, CFG)
    off = optimal_bounded(400.0, 0.0, fz, fy, mu,
                          AllocatorConfig(method="optimal_bounded", friction_circle=False))
    np.testing.assert_array_equal(on.torque_nm, np.zeros(4))
    np.testing.assert_allclose(off.torque_nm, np.full(4, 100.0), atol=1e-9)
