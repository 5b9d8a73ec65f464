"""QP of eq. (5)-(20): prediction matrices, unconstrained optimum, constraints, OSQP instances."""

import dataclasses
import math

import numpy as np
import pytest

from fourws_mpc.core import qp as Q
from fourws_mpc.core import qp_solver as S
from fourws_mpc.core.model import ModelParams, StateIdx, discretise

P = ModelParams()
V = 60 / 3.6


def _model(seed=0, vx=V):
    rng = np.random.default_rng(seed)
    z = np.array([rng.uniform(-0.3, 0.3), vx, rng.uniform(-0.1, 0.1), rng.uniform(-0.2, 0.2),
                  rng.uniform(-0.5, 0.5), 0.0])
    u = np.array([rng.uniform(-0.02, 0.02), rng.uniform(-0.01, 0.01), rng.uniform(-200, 200)])
    Ak, Bk, dk = discretise(z, u, P, 0.01)
    return z, u, Ak, Bk, dk


def _bounds(enabled=(True, True, True), state_bounds=False, band=(10.0, 10.0)):
    return Q.QpBounds(
        du_max=np.array([math.radians(0.8), math.radians(0.6), 300.0]),
        u_max=np.array([math.radians(30), math.radians(10), 1500.0]),
        enabled=np.array(enabled), vy_max=1.0, r_max=0.5, band_phi=band[0], band_y=band[1],
        state_bounds=state_bounds)


def test_matrix_powers_match_numpy():
    A = np.random.default_rng(1).normal(size=(9, 9)) * 0.3
    Pw = Q.matrix_powers(A, 30)
    for k in (0, 1, 2, 7, 16, 29, 30):
        np.testing.assert_allclose(Pw[k], np.linalg.matrix_power(A, k), rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("n_p,n_c", [(12, 6), (30, 10), (10, 3), (5, 5), (1, 1)])
def test_prediction_matrices_match_explicit_simulation(n_p, n_c):
    z, u, Ak, Bk, dk = _model(n_p)
    Aa, Ba, da = Q.augment(Ak, Bk, dk)
    C = Q.output_matrix()
    psi, theta, gamma = Q.prediction_matrices(Aa, Ba, C, n_p, n_c)
    rng = np.random.default_rng(7)
    dU = rng.normal(size=(n_c, 3)) * np.array([0.01, 0.01, 100.0])
    xi = np.concatenate([z, u])
    ys = []
    for i in range(n_p):
        du = dU[i] if i < n_c else np.zeros(3)
        xi = Aa @ xi + Ba @ du + da
        ys.append(C @ xi)
    expected = np.concatenate(ys)
    got = psi @ np.concatenate([z, u]) + theta @ dU.reshape(-1) + gamma @ da
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-12)
    # the augmented model itself: u(k-1) carried, ζ(k+1) = A ζ + B u + d
    xi0 = np.concatenate([z, u])
    x1 = Aa @ xi0 + Ba @ dU[0] + da
    np.testing.assert_allclose(x1[:6], Ak @ z + Bk @ (u + dU[0]) + dk)
    np.testing.assert_allclose(x1[6:], u + dU[0])


def _batch_ls_oracle(Ak, Bk, dk, z, u, ref, n_p, n_c, q, r):
    """Explicit unit-response simulation + least squares, independent of prediction_matrices."""
    def sim(dU):
        zz, uu, out = z.copy(), u.copy(), []
        for i in range(n_p):
            if i < n_c:
                uu = uu + dU[3 * i:3 * i + 3]
            zz = Ak @ zz + Bk @ uu + dk
            out.append([zz[StateIdx.PHI], zz[StateIdx.Y]])
        return np.array(out).reshape(-1)
    y0 = sim(np.zeros(3 * n_c))
    S = np.column_stack([sim(np.eye(3 * n_c)[j]) - y0 for j in range(3 * n_c)])
    w = np.sqrt(np.tile(q, n_p))
    rw = np.sqrt(np.tile(r, n_c))
    M = np.vstack([w[:, None] * S, np.diag(rw)])
    b = np.concatenate([w * (ref.reshape(-1) - y0), np.zeros(3 * n_c)])
    return np.linalg.lstsq(M, b, rcond=None)[0].reshape(n_c, 3)


@pytest.mark.parametrize("n_p,n_c", [(12, 6), (30, 10), (20, 7)])
def test_unconstrained_solution_matches_batch_least_squares(n_p, n_c):
    z, u, Ak, Bk, dk = _model(3)
    ref = np.column_stack([np.linspace(0, 0.002, n_p), z[StateIdx.Y] + np.linspace(0, 0.01, n_p)])
    q = np.array([50.0, 40.0])
    r = np.array([2e4, 2e4, 1e-4])
    qp = Q.MpcQp(S.QpSettings(eps_abs=1e-9, eps_rel=1e-9, max_iter=100000, polishing=True))
    sol = qp.solve(Ak, Bk, dk, z, u, ref, n_p, n_c, q, r, 1e3, _bounds())
    assert sol.ok, sol.status
    expected = _batch_ls_oracle(Ak, Bk, dk, z, u, ref, n_p, n_c, q, r)
    assert np.all(np.abs(sol.du_scaled) < 0.99), "test needs inactive constraints"
    scale = np.array([1e-3, 1e-3, 1.0])
    np.testing.assert_allclose(sol.du / scale, expected / scale, atol=1e-5)
    np.testing.assert_allclose(sol.u, u + np.cumsum(expected, axis=0), atol=1e-6 * 300)
    assert sol.slack == pytest.approx(0.0, abs=1e-7)


def test_first_move_matches_finite_horizon_lqr():
    """Nc = Np: the first increment equals −K0 ξ of the Riccati recursion (ref 0, d 0)."""
    n = 15
    z, u, Ak, Bk, _ = _model(4)
    dk = np.zeros(6)
    Aa, Ba, _ = Q.augment(Ak, Bk, dk)
    C = Q.output_matrix()[:2]
    q = np.array([50.0, 40.0])
    r = np.array([3e4, 3e4, 1e-3])
    Qy = C.T @ np.diag(q) @ C
    Pm = Qy.copy()
    for i in range(n - 1, -1, -1):
        K = np.linalg.solve(np.diag(r) + Ba.T @ Pm @ Ba, Ba.T @ Pm @ Aa)
        Pm = (Qy if i >= 1 else 0 * Qy) + Aa.T @ Pm @ (Aa - Ba @ K)
    xi = np.concatenate([z, u])
    du0 = -K @ xi
    qp = Q.MpcQp(S.QpSettings(eps_abs=1e-10, eps_rel=1e-10, max_iter=200000, polishing=True))
    sol = qp.solve(Ak, Bk, dk, z, u, np.zeros((n, 2)), n, n, q, r, 1e3,
                   _bounds(band=(100.0, 100.0)))
    assert sol.ok
    assert np.all(np.abs(sol.du_scaled) < 0.99)
    np.testing.assert_allclose(sol.du[0] / [1e-3, 1e-3, 1], du0 / [1e-3, 1e-3, 1], atol=1e-5)


@pytest.mark.parametrize("enabled", [(True, True, True), (True, False, False), (True, True, False)])
@pytest.mark.parametrize("start_deg", [0.0, 29.7])
def test_constraints_are_respected(enabled, start_deg):
    z, u, Ak, Bk, dk = _model(5)
    u = np.array([math.radians(start_deg), 0.0, 0.0])
    n_p, n_c = 20, 8
    ref = np.column_stack([np.full(n_p, 0.3), np.full(n_p, 5.0)])   # far away: wants a lot
    qp = Q.MpcQp(S.QpSettings(eps_abs=1e-6, eps_rel=1e-6, max_iter=20000))
    b = _bounds(enabled)
    sol = qp.solve(Ak, Bk, dk, z, u, ref, n_p, n_c, np.array([50.0, 40.0]),
                   np.array([1.0, 1.0, 1e-6]), 1e3, b)
    assert sol.ok
    assert np.all(np.abs(sol.du) <= b.du_max + 1e-12)
    assert np.all(np.abs(sol.u) <= b.u_max + 1e-12)
    np.testing.assert_allclose(sol.u, u + np.cumsum(sol.du, axis=0), atol=1e-9)
    for c, on in enumerate(enabled):
        if not on:
            assert np.all(sol.du[:, c] == 0.0) and np.all(sol.u[:, c] == 0.0)
    if start_deg == 0.0:       # the rate bound is active on the first move
        assert sol.du_scaled[0, 0] == pytest.approx(1.0, abs=1e-3)
    else:                      # the position bound is reached
        assert sol.u[:, 0].max() == pytest.approx(math.radians(30), abs=1e-5)


def test_soft_bounds_use_the_slack():
    z, u, Ak, Bk, dk = _model(6)
    n_p, n_c = 12, 6
    ref = np.column_stack([np.zeros(n_p), np.full(n_p, z[StateIdx.Y] + 2.0)])  # 2 m off
    qp = Q.MpcQp(S.QpSettings(eps_abs=1e-7, eps_rel=1e-7, max_iter=50000))
    sol = qp.solve(Ak, Bk, dk, z, u, ref, n_p, n_c, np.array([1.0, 1.0]),
                   np.array([1.0, 1.0, 1.0]), 1.0, _bounds(band=(math.radians(8), 0.5)))
    assert sol.ok
    # |Y − Y_ref| ≈ 2 m > 0.5 m band: ε ≥ (2 − 0.5)/0.5 − tiny movement within 0.12 s
    assert sol.slack > 2.5


def test_hard_state_bounds_hold_and_infeasibility_is_reported():
    z, u, Ak, Bk, dk = _model(7)
    n_p, n_c = 12, 6
    ref = np.column_stack([np.zeros(n_p), np.full(n_p, z[StateIdx.Y] + 1.0)])
    qp = Q.MpcQp(S.QpSettings(eps_abs=1e-7, eps_rel=1e-7, max_iter=50000))
    b = _bounds(state_bounds=True)
    b = Q.QpBounds(b.du_max, b.u_max, b.enabled, vy_max=0.35, r_max=0.25, band_phi=1.0,
                   band_y=5.0, state_bounds=True)
    sol = qp.solve(Ak, Bk, dk, z, u, ref, n_p, n_c, np.array([1.0, 1e3]),
                   np.array([1e-3, 1e-3, 1e-3]), 1.0, b)
    assert sol.ok
    Aa, Ba, da = Q.augment(Ak, Bk, dk)
    xi = np.concatenate([z, u])
    for i in range(n_p):
        xi = Aa @ xi + Ba @ (sol.du[i] if i < n_c else np.zeros(3)) + da
        assert abs(xi[StateIdx.VY]) <= 0.35 + 1e-4
        assert abs(xi[StateIdx.R]) <= 0.25 + 1e-4
    # a yaw rate far above its bound cannot be brought back within one step: infeasible
    z2 = z.copy()
    z2[StateIdx.R] = 0.6
    Ak, Bk, dk = discretise(z2, u, P, 0.01)
    sol = qp.solve(Ak, Bk, dk, z2, u, ref, n_p, n_c, np.array([1.0, 1e3]),
                   np.array([1e-3, 1e-3, 1e-3]), 1.0, b)
    assert not sol.ok
    assert "infeasible" in sol.status
    assert np.all(np.isfinite(sol.du))


def test_one_warm_started_instance_per_horizon_pair():
    z, u, Ak, Bk, dk = _model(8)
    qp = Q.MpcQp(solver=S.OsqpSolver(S.QpSettings()))
    args = (np.array([50.0, 40.0]), np.array([1e4, 1e4, 1e-4]), 1e3, _bounds())
    ref = np.zeros((30, 2))
    qp.solve(Ak, Bk, dk, z, u, ref[:12], 12, 6, *args)
    inst = qp.instance(12, 6)
    solver = qp.solver.instances[(12, 6)]
    qp.solve(Ak, Bk, dk, z, u, ref[:20], 20, 7, *args)
    sol = qp.solve(Ak, Bk, dk, z, u, ref[:12], 12, 6, *args)
    assert qp.instance(12, 6) is inst and qp.solver.instances[(12, 6)] is solver
    assert set(qp.instances) == {(12, 6), (20, 7)} == set(qp.solver.instances)
    assert inst.uses == 2
    # the second identical solve starts from the previous solution: few iterations
    sol2 = qp.solve(Ak, Bk, dk, z, u, ref[:12], 12, 6, *args, warm_du_scaled=sol.du_scaled)
    assert sol2.ok and sol2.iterations <= sol.iterations


def test_osqp_status_through_its_enum_and_one_trust_rule():
    import osqp

    assert S.osqp_status(osqp.SolverStatus.OSQP_SOLVED.value) is S.QpStatus.SOLVED
    assert S.osqp_status(osqp.SolverStatus.OSQP_MAX_ITER_REACHED.value) is \
        S.QpStatus.MAX_ITER_REACHED
    assert S.osqp_status(osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE_INACCURATE.value) is \
        S.QpStatus.PRIMAL_INFEASIBLE
    x = np.zeros(3)
    assert S.trusted(S.QpStatus.SOLVED, x, False)
    assert not S.trusted(S.QpStatus.SOLVED_INACCURATE, x, False)
    assert S.trusted(S.QpStatus.SOLVED_INACCURATE, x, True)
    assert not S.trusted(S.QpStatus.SOLVED, np.array([0.0, np.nan]), True)
    assert not S.trusted(S.QpStatus.MAX_ITER_REACHED, x, True)


def test_osqp_is_imported_by_its_solver_only_and_its_infinity_is_osqps():
    """A DAQP controller starts without osqp and scipy.sparse (0.1-0.2 s of a node's
    start); the copy of OSQP's infinity equals osqp's own."""
    import subprocess
    import sys

    import osqp

    assert float(osqp.constant("OSQP_INFTY")) == S.OSQP_INFTY
    code = ("import sys; from fourws_mpc.core.laws import warm_up; "
            "from fourws_mpc.core.config import MpcConfig; warm_up(MpcConfig()); "
            "print(sorted(m for m in ('osqp', 'scipy.sparse') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=True).stdout.strip().splitlines()[-1]
    assert out == "[]"


class _RecordingSolver:
    """A solver behind the seam that answers with OSQP and keeps what it was handed."""

    def __init__(self):
        self.inner = S.OsqpSolver(S.QpSettings())
        self.prepared, self.seen = [], []

    def prepare(self, pattern):
        self.prepared.append(pattern.key)
        self.inner.prepare(pattern)

    def solve(self, qp, warm_x):
        self.seen.append(qp)
        return self.inner.solve(qp, warm_x)

    def reset(self):
        self.inner.reset()


def test_injected_solver_gets_the_condensed_qp_and_gives_the_same_answer():
    z, u, Ak, Bk, dk = _model(3)
    args = (np.array([50.0, 40.0]), np.array([1e4, 1e4, 1e-4]), 1e3, _bounds())
    ref = np.zeros((12, 2))
    rec = _RecordingSolver()
    a = Q.MpcQp(solver=rec).solve(Ak, Bk, dk, z, u, ref, 12, 6, *args)
    b = Q.MpcQp(solver=S.OsqpSolver(S.QpSettings())).solve(Ak, Bk, dk, z, u, ref, 12, 6, *args)
    assert rec.prepared == [(12, 6)]
    qp = rec.seen[0]
    assert qp.H.shape == (18, 18) and qp.A.shape == (qp.pattern.m, 19)
    np.testing.assert_allclose(qp.H, qp.H.T, rtol=1e-12, atol=1e-12)  # upper triangle read
    assert qp.slack_hessian == 2e3
    assert a.ok and b.ok and np.array_equal(a.u, b.u) and a.code is S.QpStatus.SOLVED


def test_unknown_solver_or_model_is_a_clear_error():
    from fourws_mpc.core.model import ModelParams
    from fourws_mpc.core.prediction_model import make_prediction_model

    with pytest.raises(ValueError, match="qp_solver.*known:.*osqp"):
        S.make_qp_solver("cplex", S.QpSettings())
    with pytest.raises(ValueError, match="prediction_model.*single_track"):
        make_prediction_model("bicycle9", ModelParams())


@pytest.mark.parametrize("seed", [0, 3, 5, 9])
def test_daqp_gives_the_active_set_solution_osqp_approaches(seed):
    """DAQP (dense dual active set) and a tightly converged, polished OSQP solve the same
    condensed QPs, with the rate and position bounds active: same increments to 1e-6 of their
    bounds, DAQP's feasible to 1e-9 and its cost no higher (it is the exact optimum)."""
    z, u, Ak, Bk, dk = _model(seed)
    n_p, n_c = 20, 8
    ref = np.column_stack([np.full(n_p, 0.2), np.full(n_p, z[StateIdx.Y] + 3.0)])
    args = (Ak, Bk, dk, z, u, ref, n_p, n_c, np.array([50.0, 40.0]),
            np.array([1.0, 1.0, 1e-6]), 1e3, _bounds())
    seen = []

    class Keep(S.DaqpSolver):
        def solve(self, qp, warm_x):
            seen.append(qp)
            return super().solve(qp, warm_x)

    d = Q.MpcQp(solver=Keep(S.QpSettings())).solve(*args)
    o = Q.MpcQp(S.QpSettings(eps_abs=1e-10, eps_rel=1e-10, max_iter=200000,
                             polishing=True)).solve(*args)
    assert d.ok and o.ok and d.code is S.QpStatus.SOLVED
    np.testing.assert_allclose(d.du_scaled, o.du_scaled, atol=1e-6)
    qp = seen[0]
    x = np.concatenate([d.du_scaled.ravel(), [d.slack]])
    Az = qp.A @ x
    assert np.all(Az >= qp.lo - 1e-9) and np.all(Az <= qp.hi + 1e-9)
    assert np.any(np.isclose(np.abs(d.du_scaled), 1.0, atol=1e-9)), "no bound active"

    def cost(v):
        return 0.5 * v[:-1] @ qp.H @ v[:-1] + 0.5 * qp.slack_hessian * v[-1] ** 2 + qp.q @ v

    xo = np.concatenate([o.du_scaled.ravel(), [o.slack]])
    assert cost(x) <= cost(xo) + 1e-9


def test_daqp_reports_infeasibility_and_refuses_bad_data():
    z, u, Ak, Bk, dk = _model(7)
    z[StateIdx.R] = 0.6             # far above the hard yaw-rate bound (as above)
    Ak, Bk, dk = discretise(z, u, P, 0.01)
    n_p, n_c = 12, 6
    ref = np.column_stack([np.zeros(n_p), np.full(n_p, z[StateIdx.Y] + 1.0)])
    b = _bounds(state_bounds=True)
    b = Q.QpBounds(b.du_max, b.u_max, b.enabled, vy_max=0.35, r_max=0.25, band_phi=1.0,
                   band_y=5.0, state_bounds=True)
    qp = Q.MpcQp(solver=S.DaqpSolver(S.QpSettings()))
    sol = qp.solve(Ak, Bk, dk, z, u, ref, n_p, n_c, np.array([1.0, 1e3]),
                   np.array([1e-3, 1e-3, 1e-3]), 1.0, b)
    assert not sol.ok and sol.code is S.QpStatus.PRIMAL_INFEASIBLE
    assert np.all(np.isfinite(sol.du))
    dk_bad = dk.copy()
    dk_bad[0] = np.nan
    sol = qp.solve(Ak, Bk, dk_bad, z, u, ref, n_p, n_c, np.array([1.0, 1e3]),
                   np.array([1e-3, 1e-3, 1e-3]), 1.0, _bounds())
    assert not sol.ok and sol.code is S.QpStatus.INVALID_DATA


@pytest.mark.parametrize("n_p,n_c", [(5, 2), (12, 6), (30, 10)])
def test_the_rows_handed_over_as_simple_bounds_are_the_identity(n_p, n_c):
    """DAQP gets the layout's first ``pattern.simple`` rows as bounds on z itself: they must
    be I, so that l ≤ z ≤ u is the same constraint as l ≤ A z ≤ u on those rows."""
    inst = Q.QpLayout(n_p, n_c)
    nz = inst.pattern.simple
    assert nz == inst.nz
    mask = inst._a_mask()
    np.testing.assert_array_equal(mask[:nz], np.eye(nz, dtype=bool))
    np.testing.assert_array_equal(inst.A[:nz], np.eye(nz))


@pytest.mark.parametrize("bad", ["nan_q", "inf_a", "nan_lo", "inf_lo", "neg_inf_hi", "l_gt_u",
                                 "overflow"])
def test_the_data_check_finds_every_bad_entry(bad):
    """The fast path (sums) and the whole check agree: every kind of bad entry is found,
    and finite data whose sum overflows is still accepted."""
    rng = np.random.default_rng(3)
    q, P, A = rng.normal(size=5), rng.normal(size=(5, 5)), rng.normal(size=(8, 5))
    lo, hi = -np.ones(8), np.ones(8)
    lo[0], hi[1] = -np.inf, np.inf
    if bad == "nan_q":
        q[2] = np.nan
    elif bad == "inf_a":
        A[3, 1] = -np.inf
    elif bad == "nan_lo":
        lo[4] = np.nan
    elif bad == "inf_lo":
        lo[5] = np.inf
    elif bad == "neg_inf_hi":
        hi[6] = -np.inf
    elif bad == "l_gt_u":
        lo[7] = 2.0
    else:
        P[0, 0] = P[1, 1] = 1.7e308
        assert S.invalid_data(q, lo, hi, P, A) == ""
        return
    assert S.invalid_data(q, lo, hi, P, A) != ""


def test_the_closed_loop_with_daqp_follows_the_osqp_one_within_solver_tolerance():
    """The exact DAQP solution and OSQP's (ε_rel = 1e-4) drive the same closed loop: every
    state trace agrees to 1e-4 of its own peak (OSQP's relative tolerance carried through
    the loop), and to 1 µm in position. (An absolute 1e-6 on every trace held until the
    yaw-moment level penalty: the yaw rate then differed by 1.1e-6 rad/s of 0.068.)"""
    from fourws_bringup.core.closed_loop import run_closed_loop

    runs = {s: run_closed_loop("dlc_60_mu05", "improved", max_steps=400,
                               mpc_overrides={"qp_solver": s}) for s in ("osqp", "daqp")}
    for key in ("y", "yaw", "yaw_rate"):
        ref = runs["osqp"].state[key]
        np.testing.assert_allclose(runs["daqp"].state[key], ref, rtol=0,
                                   atol=1e-4 * float(np.abs(ref).max()), err_msg=key)
    np.testing.assert_allclose(runs["daqp"].state["y"], runs["osqp"].state["y"], rtol=0,
                               atol=1e-6)
    assert not np.any(runs["daqp"].mpc["fallback"])


def test_the_input_level_cost_is_the_sum_of_the_held_levels_over_the_horizon():
    """qp.input_level_cost: u(k+i) = u(k−1) + Σ_{j ≤ min(i, Nc−1)} Δu_j for i = 0..Np−1;
    the quadratic form of (M, w) plus its linear and constant parts equals
    Σ_i ‖u(k+i)‖²_S computed step by step."""
    from fourws_mpc.core.qp import input_level_cost

    rng = np.random.default_rng(5)
    n_p, n_c = 12, 4
    D = np.tile([0.014, 0.010, 300.0], n_c)
    s = np.array([0.0, 2.0, 1e-5])
    M, w = input_level_cost(n_p, n_c, D, s)
    u_prev = np.array([0.01, -0.004, 250.0])
    dz = rng.uniform(-1, 1, 3 * n_c)
    du = (dz * D).reshape(n_c, 3)
    direct = 0.0
    u = u_prev.copy()
    for i in range(n_p):
        if i < n_c:
            u = u + du[i]
        direct += float(u @ (s * u))
    u_t = np.tile(u_prev, n_c)
    quad = dz @ M.T @ (w * (M @ dz)) + 2 * u_t @ (w * (M @ dz)) + u_t @ (w * u_t)
    assert quad == pytest.approx(direct, rel=1e-12)


@pytest.mark.parametrize("bad", [
    {"ref": np.zeros((14, 2))},             # more reference rows than N_p: past the buffers
    {"ref": np.zeros((8, 2))},              # fewer: rows of an earlier solve would be kept
    {"n_c": 13},                            # N_c > N_p: a negative level weight
    {"n_c": 0},
    {"u_prev": np.zeros(2)},
    {"q_eff": np.ones(3)},
    {"r_eff": np.ones(2)},
    {"dk": np.zeros(5)},
    {"s_level": np.ones(2)},
    {"warm_du_scaled": np.zeros((5, 3))},
    {"terminal_w": np.eye(4)},               # a 6-state model's W has 5 or 6 rows
    {"bounds": "u_max"}, {"bounds": "du_max"}, {"bounds": "enabled"},
])
def test_a_step_of_the_wrong_shape_is_refused_before_anything_changes(bad):
    z, u, Ak, Bk, dk = _model(4)
    qp = Q.MpcQp(solver=S.DaqpSolver(S.QpSettings()))
    good = dict(Ak=Ak, Bk=Bk, dk=dk, zeta0=z, u_prev=u, ref=np.zeros((12, 2)), n_p=12, n_c=6,
                q_eff=np.array([50.0, 40.0]), r_eff=np.array([1e4, 1e4, 1e-4]), rho=1e3,
                bounds=_bounds())
    ok = qp.solve(**good)
    if bad.get("bounds"):
        name = bad["bounds"]
        bad = {"bounds": dataclasses.replace(_bounds(), **{name: getattr(_bounds(), name)[:2]})}
    before = dict(qp.instances)
    inst = qp.instance(12, 6)
    buffers = [a.copy() for a in (inst.A, inst.lo, inst.hi)]
    with pytest.raises(ValueError):
        qp.solve(**{**good, **bad, "n_p": 13, "ref": np.zeros((13, 2))} if "terminal_w" in bad
                 else {**good, **bad})
    assert qp.instances == before and inst.uses == 1
    after = (inst.A, inst.lo, inst.hi)
    assert all(np.array_equal(a, b) for a, b in zip(after, buffers, strict=True))
    again = qp.solve(**good)
    assert again.ok and np.array_equal(again.u, ok.u)


def test_the_terminal_cost_needs_two_prediction_steps():
    from fourws_mpc.core.terminal_cost import terminal_weight
    z, u, Ak, Bk, dk = _model(5)
    q, r = np.array([50.0, 40.0]), np.array([1e4, 1e4, 1e-4])
    W = terminal_weight(Ak, Bk, np.ones(3, bool), q, r)
    qp = Q.MpcQp(solver=S.DaqpSolver(S.QpSettings()))
    with pytest.raises(ValueError, match="N_p >= 2"):
        qp.solve(Ak, Bk, dk, z, u, np.zeros((1, 2)), 1, 1, q, r, 1e3, _bounds(), terminal_w=W)
    assert qp.solve(Ak, Bk, dk, z, u, np.zeros((2, 2)), 2, 1, q, r, 1e3, _bounds(),
                    terminal_w=W).ok



@pytest.mark.parametrize("bad", [{"n_c": 13}, {"s_level": np.ones(2)}, {"du_max": np.ones(2)},
                                 {"enabled": np.ones(2, bool)}, {"dk": np.zeros(5)}])
def test_the_unconstrained_gain_refuses_what_the_step_refuses(bad):
    z, u, Ak, Bk, dk = _model(6)
    good = dict(Ak=Ak, Bk=Bk, dk=dk, n_p=12, n_c=6, q_eff=np.array([50.0, 40.0]),
                r_eff=np.array([1e4, 1e4, 1e-4]), du_max=_bounds().du_max,
                enabled=_bounds().enabled)
    assert np.all(np.isfinite(Q.unconstrained_gain(**good)))
    with pytest.raises(ValueError):
        Q.unconstrained_gain(**{**good, **bad})
