"""The velocity-form LQR terminal cost (``terminal_cost``, beyond the paper): with it, the
unconstrained MPC whose control horizon spans its prediction horizon is the infinite-horizon
LQR of the same stage cost, whatever the horizon (with front steer alone, of the stage cost
without the heading level, which its terminal cost leaves out)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from fourws_bringup.core.margins import model_matrices
from fourws_mpc.core import qp as Q
from fourws_mpc.core import terminal_cost as T
from fourws_mpc.core.config import MpcConfig
from fourws_mpc.core.cost_scaling import effective_weights
from fourws_mpc.core.model import N_INPUT, StateIdx

V = 60.0 / 3.6
ROOT = Path(__file__).resolve().parents[2]


def _straight_model(cfg: MpcConfig, vx: float = V):
    """(A_k, B_k, d_k) of the shipped prediction model at rest on a straight
    (``margins.model_matrices``, what ``fourws margins`` analyses) and that state ζ0."""
    Ak, Bk, dk = model_matrices(cfg, vx)
    zeta = np.zeros(Ak.shape[0])
    zeta[StateIdx.VX] = vx
    return zeta, Ak, Bk, dk


def _wide_bounds(enabled):
    return Q.QpBounds(du_max=np.array([0.5, 0.5, 5.0e4]), u_max=np.array([1.0, 1.0, 1.0e6]),
                      enabled=np.asarray(enabled), vy_max=10.0, r_max=10.0,
                      band_phi=10.0, band_y=10.0, state_bounds=False)


def _weights(cfg: MpcConfig):
    return effective_weights(cfg, cfg.q_phi, cfg.q_y, cfg.r_ddelta, cfg.r_dmz)


@pytest.mark.parametrize("enabled", [(True, True, True), (True, True, False)])
@pytest.mark.parametrize("n_p", [4, 12, 30])
def test_with_the_terminal_cost_the_first_move_is_the_infinite_horizon_lqr(enabled, n_p):
    """A 1 cm offset at rest on a straight (an equilibrium: Δx = 0), N_c = N_p, no bound
    active: the QP's first increment equals −K z0 of the DARE on the velocity-form model,
    for every horizon; without the terminal cost it does not."""
    cfg = MpcConfig()
    zeta, Ak, Bk, dk = _straight_model(cfg)
    zeta[StateIdx.Y] = 0.01
    q_eff, r_eff = _weights(cfg)
    en = np.array(enabled)
    A_z, B_z = T.velocity_form(Ak, Bk, en)
    n_z = A_z.shape[0]
    Q_z = np.zeros((n_z, n_z))
    Q_z[-2:, -2:] = np.diag(q_eff)
    R = np.diag(r_eff[en])
    P = scipy.linalg.solve_discrete_are(A_z, B_z, Q_z, R)
    K = np.linalg.solve(R + B_z.T @ P @ B_z, B_z.T @ P @ A_z)
    z0 = np.zeros(n_z)
    z0[-1] = 0.01                                   # e_Y; Δx = 0 at the equilibrium
    lqr_du = -K @ z0
    W = T.terminal_weight(Ak, Bk, en, q_eff, r_eff)
    assert np.all(np.linalg.eigvalsh(W) > -1e-9 * np.abs(W).max())
    qp = Q.MpcQp()
    ref = np.zeros((n_p, 2))
    args = (Ak, Bk, dk, zeta, np.zeros(N_INPUT), ref, n_p, n_p, q_eff, r_eff, 1.0e6,
            _wide_bounds(enabled))
    sol = qp.solve(*args, terminal_w=W)
    assert sol.ok
    np.testing.assert_allclose(sol.du[0][en], lqr_du, rtol=1e-5, atol=1e-9)
    np.testing.assert_array_equal(sol.du[0][~en], 0.0)
    if n_p <= 12:                 # the paper's cost alone is the LQR only for a long horizon
        plain = qp.solve(*args)
        assert not np.allclose(plain.du[0][en], lqr_du, rtol=1e-2)


@pytest.mark.parametrize("n_p", [4, 12, 30])
def test_front_steer_alone_its_first_move_is_the_lqr_without_the_heading_level(n_p):
    """Front steer alone, z carries Y's level only. With q_φ = 0 (the stage cost its DARE
    prices) the QP's first increment equals −K z0 of the DARE for every horizon; without the
    terminal cost it does not."""
    cfg = MpcConfig(use_rear_steer=False, use_dyc=False, q_phi=0.0)
    zeta, Ak, Bk, dk = _straight_model(cfg)
    zeta[StateIdx.Y] = 0.01
    q_eff, r_eff = _weights(cfg)
    en = cfg.enabled
    A_z, B_z = T.velocity_form(Ak, Bk, en)
    n_z = A_z.shape[0]
    assert n_z == len(T.lateral_rows(Ak.shape[0])) + 1
    Q_z = np.zeros((n_z, n_z))
    Q_z[-1, -1] = q_eff[1]
    R = np.diag(r_eff[en])
    P = scipy.linalg.solve_discrete_are(A_z, B_z, Q_z, R)
    K = np.linalg.solve(R + B_z.T @ P @ B_z, B_z.T @ P @ A_z)
    z0 = np.zeros(n_z)
    z0[-1] = 0.01
    W = T.terminal_weight(Ak, Bk, en, q_eff, r_eff)
    np.testing.assert_allclose(W, P - Q_z, rtol=0, atol=1e-9 * np.abs(P).max())
    qp = Q.MpcQp()
    args = (Ak, Bk, dk, zeta, np.zeros(N_INPUT), np.zeros((n_p, 2)), n_p, n_p, q_eff, r_eff,
            1.0e6, _wide_bounds(en))
    sol = qp.solve(*args, terminal_w=W)
    np.testing.assert_allclose(sol.du[0][en], -K @ z0, rtol=1e-5, atol=1e-9)
    np.testing.assert_array_equal(sol.du[0][~en], 0.0)
    if n_p <= 12:
        assert not np.allclose(qp.solve(*args).du[0][en], -K @ z0, rtol=1e-2)


@pytest.mark.parametrize("n_levels", [2, 1])
@pytest.mark.parametrize("n_p,n_c", [(12, 5), (3, 3), (1, 1)])
def test_terminal_rows_are_the_velocity_form_state_of_a_simulated_plan(n_p, n_c, n_levels):
    """Zx ξ + Zu ΔU + Zd d̃ against an explicit simulation of the augmented model over the
    horizon, the input held after N_c (random state, plan and affine term); with φ and Y's
    levels, and with Y's alone."""
    cfg = MpcConfig()
    _, Ak, Bk, _ = _straight_model(cfg)
    rng = np.random.default_rng(3)
    dk = rng.normal(size=Ak.shape[0]) * 1e-3
    Aa, Ba, da = Q.augment(Ak, Bk, dk)
    xi0 = rng.normal(size=Aa.shape[0]) * 0.01
    dU = rng.normal(size=(n_c, N_INPUT)) * np.array([0.01, 0.01, 100.0])
    Zx, Zu, Zd = Q.terminal_rows(Aa, Ba, n_p, n_c, n_levels=n_levels)
    xs = [xi0]
    for i in range(n_p):
        du = dU[i] if i < n_c else np.zeros(N_INPUT)
        xs.append(Aa @ xs[-1] + Ba @ du + da)
    rows = T.lateral_rows(Ak.shape[0])
    levels = [StateIdx.PHI, StateIdx.Y][2 - n_levels:]
    expected = np.concatenate([xs[n_p][rows] - xs[n_p - 1][rows], xs[n_p][levels]])
    np.testing.assert_allclose(Zx @ xi0 + Zu @ dU.reshape(-1) + Zd @ da, expected,
                               rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("n_levels", [2, 1])
def test_a_car_on_a_turning_reference_owes_no_terminal_cost_for_its_heading_and_offset(
        n_levels):
    """The reference's own motion is the target of Δφ and ΔY: a plan whose φ and Y are the
    reference's (here the reference is the car's own free prediction through a turn) leaves
    the e rows and the Δφ, ΔY rows of the terminal error at zero; with Y's level alone (front
    steer) its e row holds Y_ref's level, not φ_ref's."""
    cfg = MpcConfig()
    zeta, Ak, Bk, dk = _straight_model(cfg)
    zeta[StateIdx.R] = 0.15                  # turning at 0.15 rad/s
    zeta[StateIdx.VY] = 0.1
    Aa, Ba, da = Q.augment(Ak, Bk, dk)
    n_p, n_c = 12, 4
    xi = np.concatenate([zeta, [0.02, 0.0, 0.0]])
    xs = [xi]
    for _ in range(n_p):
        xs.append(Aa @ xs[-1] + da)
    ref = np.array([[x[StateIdx.PHI], x[StateIdx.Y]] for x in xs[1:]])
    assert abs(ref[-1, 0] - ref[-2, 0]) > 1e-3       # the reference turns
    Zx, _, Zd = Q.terminal_rows(Aa, Ba, n_p, n_c, n_levels=n_levels)
    z_ref = T.reference_rows(ref, Ak.shape[0], n_levels)
    z = Zx @ xi + Zd @ da - z_ref
    rows = list(T.lateral_rows(Ak.shape[0]))
    on_path = [rows.index(StateIdx.PHI), rows.index(StateIdx.Y),
               *range(len(rows), len(rows) + n_levels)]
    np.testing.assert_allclose(z[on_path], 0.0, atol=1e-12)
    np.testing.assert_array_equal(z_ref[len(rows):], ref[-1, 2 - n_levels:])


@pytest.mark.parametrize("enabled", [(True, True, True), (True, False, False)])
def test_the_reference_enters_with_its_sign(enabled):
    """A car 1 cm left of a reference at Y = 0 and a car at Y = 0 beside a reference 1 cm
    right of it make the same first move, with both levels in the terminal cost and with Y's
    alone (front steer)."""
    cfg = MpcConfig()
    zeta, Ak, Bk, dk = _straight_model(cfg)
    q_eff, r_eff = _weights(cfg)
    en = np.array(enabled)
    W = T.terminal_weight(Ak, Bk, en, q_eff, r_eff)
    qp = Q.MpcQp()
    moves = []
    for y, y_ref in ((0.01, 0.0), (0.0, -0.01)):
        z0 = zeta.copy()
        z0[StateIdx.Y] = y
        ref = np.zeros((12, 2))
        ref[:, 1] = y_ref
        sol = qp.solve(Ak, Bk, dk, z0, np.zeros(N_INPUT), ref, 12, 12, q_eff, r_eff, 1.0e6,
                       _wide_bounds(en), terminal_w=W)
        moves.append(sol.du[0])
    np.testing.assert_allclose(moves[0], moves[1], rtol=1e-9, atol=1e-12)


def test_front_steer_alone_cannot_hold_both_levels_but_can_hold_y():
    """Why z carries Y's level alone with one input: with both levels the velocity form has
    a mode at 1 that the one input cannot steer (PBH rank), so no stabilising DARE solution
    exists; with Y's alone it is stabilisable. No input at all is a clear error."""
    cfg = MpcConfig()
    _, Ak, Bk, _ = _straight_model(cfg)
    q_eff, r_eff = _weights(cfg)
    n = Ak.shape[0]
    rows, cols = T.lateral_rows(n), np.array([0])
    for n_levels, stabilisable in ((2, False), (1, True)):
        A_z, B_z = T._velocity_form(np.ascontiguousarray(Ak), np.ascontiguousarray(Bk), rows,
                                    cols, T.output_index(n, n_levels))
        n_z = A_z.shape[0]
        rank = np.linalg.matrix_rank(np.hstack([A_z - np.eye(n_z), B_z]))
        assert (rank == n_z) == stabilisable, (n_levels, rank, n_z)
    W = T.terminal_weight(Ak, Bk, np.array([True, False, False]), q_eff, r_eff)
    assert W.shape == (len(rows) + 1,) * 2
    assert np.all(np.linalg.eigvalsh(W) > -1e-9 * np.abs(W).max())
    with pytest.raises(ValueError, match="no input enabled"):
        T.terminal_weight(Ak, Bk, np.zeros(3, bool), q_eff, r_eff)


def _dare_residual(A, B, Q, R, P):
    BtPA = B.T @ P @ A
    res = A.T @ P @ A - P - BtPA.T @ np.linalg.solve(R + B.T @ P @ B, BtPA) + Q
    return np.abs(res).max() / np.abs(P).max()


@pytest.mark.parametrize("seed", range(8))
def test_the_doubling_dare_is_scipys_stabilising_solution(seed):
    """``solve_dare`` (structure-preserving doubling) against scipy's QZ solver, the oracle:
    random systems with unstable modes and a singular Q (observable through A), and the
    velocity-form model (integrators at λ = 1) at 60 and 120 km/h with the package weights;
    the solution is the stabilising one (closed loop inside the unit circle) with a residual
    at round-off."""
    rng = np.random.default_rng(seed)
    n, m = 6 + seed % 5, 1 + seed % 3
    A = rng.normal(size=(n, n)) * 1.2 / math.sqrt(n)          # some eigenvalues outside
    B = rng.normal(size=(n, m))
    C = rng.normal(size=(1 + seed % 2, n))
    Q = C.T @ C                                                  # rank 1-2
    R = np.diag(rng.uniform(0.1, 10.0, m))
    P = T.solve_dare(A, B, Q, R)
    P0 = scipy.linalg.solve_discrete_are(A, B, Q, R)
    np.testing.assert_allclose(P, P0, rtol=1e-7, atol=1e-9 * np.abs(P0).max())
    K = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
    assert np.abs(np.linalg.eigvals(A - B @ K)).max() < 1.0
    assert _dare_residual(A, B, Q, R, P) < 1e-10
    cfg = MpcConfig()
    q_eff, r_eff = _weights(cfg)
    en = np.array([True, True, True])
    for kmh in (60.0, 120.0):
        Ak, Bk, _ = model_matrices(cfg, kmh / 3.6)
        A_z, B_z = T.velocity_form(Ak, Bk, en)
        Q_z = np.zeros_like(A_z)
        Q_z[-2:, -2:] = np.diag(q_eff)
        R_z = np.diag(r_eff)
        P = T.solve_dare(A_z, B_z, Q_z, R_z)
        P0 = scipy.linalg.solve_discrete_are(A_z, B_z, Q_z, R_z)
        np.testing.assert_allclose(P, P0, rtol=1e-6, atol=1e-9 * np.abs(P0).max())
        assert _dare_residual(A_z, B_z, Q_z, R_z, P) < 1e-12


def test_a_dare_without_a_stabilising_solution_is_a_clear_error():
    """An unstable mode the input cannot reach: no stabilising P; the doubling says so
    instead of returning a number (the controller then steps without the terminal cost)."""
    A = np.diag([1.1, 0.5])
    B = np.array([[0.0], [1.0]])
    with pytest.raises(np.linalg.LinAlgError, match="no stabilising solution"):
        T.solve_dare(A, B, np.eye(2), np.eye(1))


def test_the_margins_gain_is_the_controllers_first_move():
    """``fourws margins`` analyses the controller it reports on: its unconstrained gain with
    the terminal cost (``margins.mpc_gain``) gives the QP's first increment from a state the
    bounds leave free."""
    from fourws_bringup.core.margins import mpc_gain

    cfg = MpcConfig(horizons_mode="fixed", weights_mode="fixed", terminal_cost="lqr",
                    mz_level_weight=0.0)
    Ak, Bk, dk = model_matrices(cfg, V)
    zeta = np.zeros(Ak.shape[0])
    zeta[StateIdx.VX] = V
    zeta[StateIdx.Y] = 0.002
    K = mpc_gain(cfg, V)
    q_eff, r_eff = _weights(cfg)
    W = T.terminal_weight(Ak, Bk, cfg.enabled, q_eff, r_eff)
    bounds = Q.QpBounds(du_max=cfg.du_max, u_max=np.full(3, 1e6), enabled=cfg.enabled,
                        vy_max=10.0, r_max=10.0, band_phi=10.0, band_y=10.0,
                        state_bounds=False)
    sol = Q.MpcQp().solve(Ak, Bk, dk, zeta, np.zeros(N_INPUT),
                          np.zeros((cfg.np_baseline, 2)), cfg.np_baseline, cfg.nc_baseline,
                          q_eff, r_eff, cfg.rho, bounds, terminal_w=W)
    assert np.all(np.abs(sol.du_scaled[0]) < 0.99)          # no increment bound active
    np.testing.assert_allclose(sol.du[0], -K @ np.concatenate([zeta, np.zeros(N_INPUT)]),
                               rtol=1e-5, atol=1e-9)


def test_the_terminal_cost_keeps_a_soft_short_horizon_stable():
    """The reason for it: at N_p 12 a soft lateral weight (s_Y 95 mm) leaves the paper's cost
    with a slow loop; with the terminal cost the same weights give the LQR's decay (the
    margins' closed loop, ideal world)."""
    from fourws_bringup.core.margins import spectral_radius
    from fourws_sim.core.vehicle_params import VehicleParams

    base = MpcConfig(np_baseline=12, nc_baseline=12, horizons_mode="fixed",
                     weights_mode="fixed", scale_y_m=0.095)
    v = VehicleParams()
    with_t = spectral_radius(dataclasses.replace(base, terminal_cost="lqr"), v, V)
    without = spectral_radius(base, v, V)
    assert with_t < without
    assert with_t < 0.995 and math.isfinite(with_t)


@pytest.mark.parametrize("controller", ["improved", "mpc_fws"])
def test_across_a_run_the_reused_cost_to_go_equals_a_full_solve(monkeypatch, controller):
    """A run with a steady straight (the bench's 30 s lead-out): the controller has its
    terminal weight on every step (front steer alone too: none is skipped), reuses it on some
    steps, and every weight it used equals a DARE solved afresh on that step's data to 1e-9
    relative."""
    from fourws_bringup.core.closed_loop import run_closed_loop
    from fourws_mpc.core.controller import TERMINAL_COST_SKIPPED

    used = []
    call = T.TerminalWeight.__call__

    def record(self, Ak, Bk, enabled, q_eff, r_eff):
        W = call(self, Ak, Bk, enabled, q_eff, r_eff)
        used.append((Ak.copy(), Bk.copy(), np.array(enabled), np.array(q_eff, float),
                     np.array(r_eff, float), W.copy(), self.reuses))
        return W

    monkeypatch.setattr(T.TerminalWeight, "__call__", record)
    log = run_closed_loop(str(ROOT / "benchmarks/scenarios/bench_dlc_60_mu05.yaml"),
                          controller, max_steps=2500)
    monkeypatch.undo()
    assert not [st for st in log.solver_status if TERMINAL_COST_SKIPPED in st]
    reuses = used[-1][-1]
    assert len(used) == 2500 and reuses > 100, f"{reuses} reuses in {len(used)} steps"
    worst = max(np.max(np.abs(W - T.terminal_weight(Ak, Bk, en, q, r))) / np.max(np.abs(W))
                for Ak, Bk, en, q, r, W, _ in used)
    assert worst <= 1e-9


@pytest.mark.parametrize("A, B, Q, R", [
    # a slow mode weakly weighted and weakly reached (closed loop ≈ 0.999): slow linear phase
    (np.diag([0.999, 0.5]), np.array([[1e-3], [1.0]]), np.diag([1e-6, 1.0]), np.eye(1)),
    # a double integrator with a dear input: a sluggish, lightly damped closed loop
    (np.array([[1.0, 0.01], [0.0, 1.0]]), np.array([[0.0], [0.01]]), np.diag([1.0, 0.0]),
     1e4 * np.eye(1)),
    (np.diag([0.9999, 0.3]), np.array([[1e-4], [1.0]]), np.diag([1e-3, 1.0]), np.eye(1)),
    # a slow mode Q barely weighs beside a fast one (a review's counter-examples)
    (np.diag([0.0, 0.9999]), np.array([[1.0], [1e-4]]), np.diag([1.0, 1e-8]), np.eye(1)),
    (np.diag([0.5, 0.9999]), np.array([[1.0], [1e-4]]), np.diag([1.0, 1e-10]), np.eye(1)),
])
def test_the_doubling_stops_only_once_it_converged(A, B, Q, R):
    """The doubling stops where a doubling run to a change of 1e-26 ends, on closed loops
    whose slow modes, weakly weighted or weakly reached, move P little per doubling long
    before they converge."""
    P = T.solve_dare(A, B, Q, R)
    strict, ok = T._sda(A, B, Q, R, 1e-26, 60)
    assert ok
    np.testing.assert_allclose(P, strict, rtol=0, atol=1e-13 * np.abs(strict).max())
    assert _dare_residual(A, B, Q, R, P) < 1e-13
