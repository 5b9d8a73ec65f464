"""Builds the condensed QP of one MPC step, compiled (numba): eq. (5)-(6), (16)-(20) as in ``qp``.

:func:`condense` fills, for one (N_p, N_c), the Hessian H and gradient g of the scaled
increments ΔŨ and the rows of the constraint matrix and bounds that change every step. It is
the 100 Hz path of :meth:`fourws_mpc.core.qp.MpcQp.solve`; the numpy forms in ``qp``
(:func:`~fourws_mpc.core.qp.prediction_matrices`, :func:`~fourws_mpc.core.qp.terminal_rows`,
:func:`~fourws_mpc.core.qp.input_level_cost`) state the same maths matrix by matrix and are
its oracle in the unit tests (docs/mpc.md, "The QP").

With the augmented model ξ(k+1) = Ã ξ + B̃ Δu + d̃ of eq. (5), the stages are:

1. **free response** x_i = Ã x_{i−1} + d̃, x_0 = ξ (i = 1..N_p): Ψ ξ + Γ d̃ of eq. (6);
2. **Markov parameters** T_m = Ã^m B̃ (m = 0..N_p−1), so that the block (i, j) of Θ is
   C T_{i−1−j} for j < min(i, N_c), scaled by D = diag(Δu_max) per column;
3. **cost** H = 2 Θ_yᵀ Q Θ_y + 2 diag(R D²), g = 2 Θ_yᵀ Q (y_free − y_ref) over the outputs
   (φ, Y); the input-level penalty adds 2 Mᵀ diag(w) M and 2 Mᵀ diag(w) u(k−1);
   the terminal cost adds 2 Z_sᵀ W Z_s and 2 Z_sᵀ W (z_free − z_ref) with the velocity-form
   rows Z of ``terminal_cost`` (lateral rows of ξ_Np − ξ_{Np−1}, then φ and Y of ξ_Np, or Y
   alone);
4. **constraints**: the rows of Θ for the hard (v_y, r) and the soft (φ, Y) bounds and their
   bounds, in the row order of :class:`~fourws_mpc.core.qp.QpLayout`.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _free_and_markov(Aa: np.ndarray, Ba: np.ndarray, da: np.ndarray, xi: np.ndarray,
                     n_p: int) -> tuple[np.ndarray, np.ndarray]:
    """Stages 1-2: free states x_0..x_Np (N_p+1, n_a) and T_0..T_{Np−1} (N_p, n_a, n_u)
    (loops: at these sizes a BLAS call per step costs more than its arithmetic)."""
    na, nu = Ba.shape
    x = np.empty((n_p + 1, na))
    x[0] = xi
    T = np.empty((n_p, na, nu))
    T[0] = Ba
    for i in range(1, n_p + 1):
        for r in range(na):
            acc = 0.0
            for k in range(na):
                acc += Aa[r, k] * x[i - 1, k]
            x[i, r] = acc + da[r]
    for m in range(1, n_p):
        for r in range(na):
            for c in range(nu):
                acc = 0.0
                for k in range(na):
                    acc += Aa[r, k] * T[m - 1, k, c]
                T[m, r, c] = acc
    return x, T


@njit(cache=True)
def _theta(T: np.ndarray, rows: np.ndarray, n_c: int, D: np.ndarray, first: int
           ) -> np.ndarray:
    """Θ D for the state rows ``rows`` at the prediction steps i = first+1..N_p:
    (N_p − first, len(rows), n_u N_c), step-major."""
    n_p, _, nu = T.shape
    nr = rows.shape[0]
    th = np.zeros((n_p - first, nr, nu * n_c))
    for i in range(first, n_p):
        for j in range(min(i + 1, n_c)):
            Tm = T[i - j]
            for o in range(nr):
                for c in range(nu):
                    th[i - first, o, j * nu + c] = Tm[rows[o], c] * D[j * nu + c]
    return th


@njit(cache=True)
def condense(Aa: np.ndarray, Ba: np.ndarray, da: np.ndarray, xi: np.ndarray,
             out_rows: np.ndarray, n_c: int, D: np.ndarray, ref: np.ndarray,
             q_eff: np.ndarray, r_eff: np.ndarray, u_prev: np.ndarray,
             s_level: np.ndarray, lat_rows: np.ndarray, out_pos: np.ndarray,
             W: np.ndarray, z_ref: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                        np.ndarray]:
    """H (3N_c, 3N_c), g (3N_c,), Θ_y D (2N_p, 3N_c) and the free errors e (2N_p,) of the
    outputs (φ, Y), Θ_h D (2N_p, 3N_c) and the free values (2N_p,) of the hard-bounded rows
    (v_y, r); see the module docstring.

    ``out_rows`` = (φ, Y, v_y, r) rows of ξ; ``ref`` (N_p, 2) = [φ_ref, Y_ref] at
    i = 1..N_p; ``D`` (3N_c,) = Δu_max tiled; ``s_level`` (3,) the level weights (zeros:
    none); ``W`` the terminal weight on z (0×0: none), ``lat_rows`` and ``out_pos`` its
    lateral rows of ξ and where its levelled outputs (φ and Y, or Y) sit among them, ``z_ref``
    its reference part.
    """
    n_p = ref.shape[0]
    nu = Ba.shape[1]
    ncol = nu * n_c
    x, T = _free_and_markov(Aa, Ba, da, xi, n_p)
    th = _theta(T, out_rows, n_c, D, 0)
    th_out = np.empty((2 * n_p, ncol))
    th_hard = np.empty((2 * n_p, ncol))
    e_free = np.empty(2 * n_p)
    hard_free = np.empty(2 * n_p)
    w = np.empty(2 * n_p)
    for i in range(n_p):
        for o in range(2):
            th_out[2 * i + o] = th[i, o]
            th_hard[2 * i + o] = th[i, 2 + o]
            e_free[2 * i + o] = x[i + 1, out_rows[o]] - ref[i, o]
            hard_free[2 * i + o] = x[i + 1, out_rows[2 + o]]
            w[2 * i + o] = q_eff[o]
    wth = th_out * w.reshape(-1, 1)
    th_out_t = np.ascontiguousarray(th_out.T)
    H = 2.0 * (th_out_t @ wth)
    g = 2.0 * (th_out_t @ (w * e_free))
    for j in range(n_c):
        for c in range(nu):
            k = j * nu + c
            H[k, k] += 2.0 * r_eff[c] * D[k] * D[k]
    if np.any(s_level != 0.0):
        # u(k+j) = u(k−1) + Σ_{l≤j} D Δũ_l; the last planned level held N_p − N_c + 1 times:
        # Mᵀ diag(w) M couples Δũ_l and Δũ_l' of one input through the weights of the
        # levels both reach, S_c(max(l, l')) with S_c(l) = Σ_{j≥l} w_j,c (a suffix sum)
        S = np.zeros((n_c + 1, nu))
        for j in range(n_c - 1, -1, -1):
            for c in range(nu):
                S[j, c] = S[j + 1, c] + s_level[c] * (n_p - n_c + 1.0 if j == n_c - 1
                                                      else 1.0)
        for c in range(nu):
            for l1 in range(n_c):
                a = l1 * nu + c
                g[a] += 2.0 * D[a] * S[l1, c] * u_prev[c]
                for l2 in range(n_c):
                    b = l2 * nu + c
                    H[a, b] += 2.0 * D[a] * D[b] * S[max(l1, l2), c]
    if W.shape[0] > 0:
        n_l = lat_rows.shape[0]
        th_l = _theta(T, lat_rows, n_c, D, max(n_p - 2, 0))   # the last two steps only
        end = th_l.shape[0] - 1
        n_e = out_pos.shape[0]
        Zs = np.empty((n_l + n_e, ncol))
        z = np.empty(n_l + n_e)
        for o in range(n_l):
            r = lat_rows[o]
            Zs[o] = th_l[end, o]
            if n_p >= 2:
                Zs[o] -= th_l[end - 1, o]
            z[o] = x[n_p, r] - x[n_p - 1, r] - z_ref[o]
        for o in range(n_e):
            Zs[n_l + o] = th_l[end, out_pos[o]]
            z[n_l + o] = x[n_p, lat_rows[out_pos[o]]] - z_ref[n_l + o]
        cross = 2.0 * (np.ascontiguousarray(Zs.T) @ W)
        H += cross @ Zs
        g += cross @ z
    return H, g, th_out, e_free, th_hard, hard_free


@njit(cache=True)
def constraints(A: np.ndarray, lo: np.ndarray, hi: np.ndarray, th_out: np.ndarray,
                e_free: np.ndarray, th_hard: np.ndarray, hard_free: np.ndarray,
                D: np.ndarray, en: np.ndarray, u_min: np.ndarray, u_max: np.ndarray,
                u_prev: np.ndarray, band: np.ndarray, vy_max: float, r_max: float,
                state_bounds: bool, from_step: int, softness: float) -> None:
    """Stage 4: the step's rows of A and the bounds (lo, hi), in place, in the row order of
    :class:`~fourws_mpc.core.qp.QpLayout` (Δũ box, ε ≥ 0, u bounds, v_y and r above and
    below (hard, or soft with ``softness`` > 0), soft φ and Y above, soft below); A's Δũ
    box and ε rows are the layout's constants."""
    n2, ncol = th_out.shape
    nu = u_prev.shape[0]
    n_c = ncol // nu
    inf = np.inf
    for k in range(ncol):
        lo[k] = -en[k]
        hi[k] = en[k]
    lo[ncol] = 0.0
    hi[ncol] = inf
    o = ncol + 1                                   # u bounds: u(k−1) + Σ_{l≤j} D Δũ_l
    for j in range(n_c):
        for c in range(nu):
            k = j * nu + c
            for m in range(n_c):
                A[o + k, m * nu + c] = D[m * nu + c] if m <= j else 0.0
            lo[o + k] = u_min[c] - u_prev[c]
            hi[o + k] = u_max[c] - u_prev[c]
    o_h = 2 * ncol + 1                             # v_y, r ≤ bound (+ c bound ε when soft)
    o_hl = o_h + n2                                # v_y, r ≥ −bound (− c bound ε)
    o_sh = o_hl + n2
    o_sl = o_sh + n2
    for i in range(n2):
        A[o_h + i, :ncol] = th_hard[i]
        A[o_hl + i, :ncol] = th_hard[i]
        A[o_sh + i, :ncol] = th_out[i]
        A[o_sh + i, ncol] = -band[i]
        A[o_sl + i, :ncol] = th_out[i]
        A[o_sl + i, ncol] = band[i]
        lim = inf
        if state_bounds and i >= 2 * (from_step - 1):
            lim = vy_max if i % 2 == 0 else r_max
        relax = softness * lim if lim < inf else 0.0
        A[o_h + i, ncol] = -relax
        A[o_hl + i, ncol] = relax
        lo[o_h + i] = -inf
        hi[o_h + i] = lim - hard_free[i]
        lo[o_hl + i] = -lim - hard_free[i]
        hi[o_hl + i] = inf
        lo[o_sh + i] = -inf
        hi[o_sh + i] = band[i] - e_free[i]
        lo[o_sl + i] = -band[i] - e_free[i]
        hi[o_sl + i] = inf
    for k in range(lo.shape[0]):                   # a u(k−1) beyond its bound: never l > u
        if lo[k] > hi[k]:
            lo[k] = hi[k]
