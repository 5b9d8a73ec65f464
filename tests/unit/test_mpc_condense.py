"""The compiled condensing (``condense``) against the numpy forms of ``qp``, the oracle.

The oracle builds H and g matrix by matrix from :func:`qp.prediction_matrices`,
:func:`qp.terminal_rows` and :func:`qp.input_level_cost` (eq. 6, 16-20), as the QP was built
before it was compiled; the compiled kernel must agree to round-off on every model size,
horizon pair and cost term."""

import math

import numpy as np
import pytest

from fourws_mpc.core import qp as Q
from fourws_mpc.core import terminal_cost as T
from fourws_mpc.core.condense import condense
from fourws_mpc.core.model import N_INPUT


def _random_model(rng, n):
    """A stable-ish random discrete model of n states with the MPC's scale (dt 10 ms)."""
    Ak = np.eye(n) + 0.01 * rng.normal(size=(n, n))
    Bk = 0.01 * rng.normal(size=(n, N_INPUT))
    dk = 0.001 * rng.normal(size=n)
    return Ak, Bk, dk


def _oracle(Ak, Bk, dk, zeta, u_prev, ref, n_c, D, q_eff, r_eff, s_level, W, n_levels=2):
    n_p = ref.shape[0]
    Aa, Ba, da = Q.augment(Ak, Bk, dk)
    xi = np.concatenate([zeta, u_prev])
    C = Q.output_matrix(n_state=Ak.shape[0])
    psi, theta, gamma = Q.prediction_matrices(Aa, Ba, C, n_p, n_c)
    free = (psi @ xi + gamma @ da).reshape(n_p, Q.N_OUT)
    th = (theta * D[None, :]).reshape(n_p, Q.N_OUT, N_INPUT * n_c)
    th_out = th[:, :2, :].reshape(2 * n_p, -1)
    th_hard = th[:, 2:, :].reshape(2 * n_p, -1)
    e_free = (free[:, :2] - ref).reshape(-1)
    w = np.repeat(q_eff[None, :], n_p, axis=0).reshape(-1)
    r_s = np.repeat(r_eff[None, :], n_c, axis=0).reshape(-1) * D * D
    H = 2.0 * (th_out.T @ (w[:, None] * th_out)) + np.diag(2.0 * r_s)
    g = 2.0 * th_out.T @ (w * e_free)
    if np.any(s_level):
        M, wl = Q.input_level_cost(n_p, n_c, D, s_level)
        H += 2.0 * (M.T @ (wl[:, None] * M))
        g += 2.0 * M.T @ (wl * np.tile(u_prev, n_c))
    if W is not None:
        Zx, Zu, Zd = Q.terminal_rows(Aa, Ba, n_p, n_c, n_levels=n_levels)
        hess, cross = T.terminal_terms(W, Zu * D[None, :])
        H += hess
        g += cross @ (Zx @ xi + Zd @ da - T.reference_rows(ref, Ak.shape[0], n_levels))
    return H, g, th_out, e_free, th_hard, free[:, 2:].reshape(-1)


@pytest.mark.parametrize("n", [6, 8, 10])
@pytest.mark.parametrize("n_p,n_c", [(1, 1), (2, 1), (12, 6), (30, 10), (10, 10)])
@pytest.mark.parametrize("terms", ["paper", "level", "terminal", "both", "terminal_y"])
def test_compiled_condensing_equals_the_numpy_forms(n, n_p, n_c, terms):
    rng = np.random.default_rng(1000 * n + 10 * n_p + n_c)
    Ak, Bk, dk = _random_model(rng, n)
    zeta = rng.normal(size=n)
    u_prev = rng.normal(size=N_INPUT) * np.array([0.02, 0.01, 300.0])
    ref = rng.normal(size=(n_p, 2))
    D = np.tile([math.radians(0.8), math.radians(0.6), 300.0], n_c)
    q_eff = rng.uniform(1.0, 100.0, 2)
    r_eff = rng.uniform(0.1, 10.0, N_INPUT)
    s_level = rng.uniform(0.1, 1.0, N_INPUT) if terms in ("level", "both") else np.zeros(3)
    W = None
    n_levels = 1 if terms == "terminal_y" else 2      # front steer alone: Y's level only
    if terms in ("terminal", "both", "terminal_y"):
        n_z = len(T.lateral_rows(n)) + n_levels
        X = rng.normal(size=(n_z, n_z))
        W = X @ X.T
    want = _oracle(Ak, Bk, dk, zeta, u_prev, ref, n_c, D, q_eff, r_eff, s_level, W, n_levels)
    Aa, Ba, da = Q.augment(Ak, Bk, dk)
    got = condense(Aa, Ba, da, np.concatenate([zeta, u_prev]), Q._OUT_ROWS, n_c, D, ref,
                   q_eff, r_eff, u_prev, s_level, T.lateral_rows(n),
                   T.output_index(n, n_levels), np.zeros((0, 0)) if W is None else W,
                   np.zeros(3) if W is None else T.reference_rows(ref, n, n_levels))
    for name, a, b in zip(("H", "g", "th_out", "e_free", "th_hard", "hard_free"), got, want,
                          strict=True):
        scale = max(np.abs(b).max(), 1e-300)
        assert np.abs(a - b).max() <= 1e-12 * scale, name
