"""Condenses the Δu MPC, eq. (5)-(6), cost eq. (16)-(19) and constraints eq. (20), into one QP.

Augmented model, eq. (5), with the affine term of the linearisation (``model.discretise``;
docs/mpc.md, "The QP")::

    ξ = [ζ; u(k−1)] (9),  Ã = [[A_k, B_k], [0, I]],  B̃ = [[B_k], [I]],  d̃ = [d_k; 0]
    ξ(k+1) = Ã ξ(k) + B̃ Δu(k) + d̃

The state dimension is the model's (taken from A_k: 6 for eq. (1), 8 with the steering
actuators of ``actuator_model``, whose states follow ``StateIdx.X``), so ξ has n + 3 entries;
the output rows and the sparsity pattern of one (Np, Nc) do not depend on it. Prediction over
i = 1..Np with Δu(k+j) = 0 for j ≥ Nc, eq. (6) plus the affine column::

    y(k+i) = C Ã^i ξ(k) + Σ_{j<min(i,Nc)} C Ã^{i−1−j} B̃ Δu(k+j) + Σ_{m<i} C Ã^m d̃
    Y = Ψ ξ + Θ ΔU + Γ d̃

C picks the rows [φ, Y, vy, r] of ξ: φ and Y are the outputs of eq. (5) (cost and soft bounds),
vy and r carry the hard bounds. Ψ, Θ and Γ come from batched matrix powers, with no Python
loop over horizon steps.

Cost, eq. (16)-(19), with the increments indexed k..k+Nc−1 (the printed eq. (16) sums from
i = 1 to Nc−1, one increment short; docs/mpc.md, "Deviations from the paper")::

    J = Σ_{i=1..Np} ‖y_i − y_ref,i‖²_Q + Σ_{j=0..Nc−1} ‖Δu_j‖²_R + ρ ε²

Q = diag(q_φ, q_Y) and R = diag(r_δf, r_δr, r_Mz) are the *effective* weights (already divided
by the squared characteristic sizes of ``cost_scaling``).

Beyond the paper (0 in its cost), two optional terms: a penalty on the input *level*
(``input_level_cost``; docs/mpc.md, "The yaw moment's level"), S = diag(s_δf, s_δr, s_Mz) on
u(k+i) = u(k−1) + Σ_{j≤min(i, Nc−1)} Δu_j (the plan held after N_c, as the prediction holds it)::

    J += Σ_{i=0..Np−1} ‖u(k+i)‖²_S

and a terminal cost (``terminal_cost``; docs/mpc.md, "A terminal cost"), the infinite-horizon
LQR's cost-to-go in velocity form, z_Npᵀ W z_Np with z = [Δx_L; φ − φ_ref; Y − Y_ref]
(z = [Δx_L; Y − Y_ref] with front steer alone).

The QP variable is z = [ΔŨ; ε] with ΔŨ = D⁻¹ ΔU, D = diag(Δu_max) repeated Nc times, so every
increment is in [−1, 1]; ε ≥ 0 is one dimensionless slack. Constraints, eq. (20) and section
3.1.5 (rows of the constraint matrix, in this order)::

    −1 ≤ Δũ_j ≤ 1                         (0 ≤ Δũ ≤ 0 for a disabled input: δr or Mz ≡ 0)
    0 ≤ ε
    u_min − u(k−1) ≤ Σ_{l≤j} D Δũ_l ≤ u_max − u(k−1)
    |vy_i| ≤ vy_max,  |r_i| ≤ r_max       hard (sideslip β ≈ vy/vx and yaw-rate bounds),
                                          for i ≥ ``state_bounds_from_step``
    |φ_i − φ_ref,i| ≤ b_φ (1 + ε),  |Y_i − Y_ref,i| ≤ b_Y (1 + ε)     soft, eq. (20)

Disabled inputs keep their columns, so every controller shares one sparsity pattern per
(Np, Nc) (:class:`QpLayout`, built once per pair and kept). Each step fills a
:class:`~fourws_mpc.core.qp_solver.CondensedQp` for the injected solver (``qp_solver``),
warm-started from the shifted previous plan; only a solution the solver calls optimal is used
(``qp_solver.trusted``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np
from numba import njit

from fourws_mpc.core.condense import condense, constraints
from fourws_mpc.core.model import N_INPUT, N_STATE, StateIdx
from fourws_mpc.core.qp_solver import (
    CondensedQp,
    DaqpSolver,
    QpPattern,
    QpSettings,
    QpSolver,
    QpStatus,
)
from fourws_mpc.core.terminal_cost import (
    OUTPUTS,
    lateral_rows,
    output_index,
    output_positions,
    reference_rows,
    reference_rows_compiled,
)

_ZERO_U = np.zeros(N_INPUT)
#: rows of the augmented state picked by C: outputs (φ, Y) then hard-bounded states (vy, r)
OUT_ROWS = (StateIdx.PHI, StateIdx.Y, StateIdx.VY, StateIdx.R)
N_OUT = len(OUT_ROWS)
_INF = np.inf
_OUT_ROWS = np.array(OUT_ROWS, dtype=np.int64)
_NO_TERMINAL = np.zeros((0, 0))


def augment(Ak: np.ndarray, Bk: np.ndarray, dk: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Augmented matrices of eq. (5) for a model of n states (A_k (n, n)): Ã (n+3, n+3),
    B̃ (n+3, 3), d̃ (n+3,); (9, 9), (9, 3), (9,) for eq. (1)."""
    f = np.ascontiguousarray
    return _augment(f(Ak, dtype=float), f(Bk, dtype=float), f(dk, dtype=float))


@njit(cache=True)
def _augment(Ak: np.ndarray, Bk: np.ndarray, dk: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`augment`, compiled."""
    n, nu = Bk.shape
    Aa = np.zeros((n + nu, n + nu))
    Ba = np.zeros((n + nu, nu))
    da = np.zeros(n + nu)
    Aa[:n, :n] = Ak
    Aa[:n, n:] = Bk
    Ba[:n] = Bk
    da[:n] = dk
    for c in range(nu):
        Aa[n + c, n + c] = 1.0
        Ba[n + c, c] = 1.0
    return Aa, Ba, da


def _as_float(x: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=float)


def _sh(a: Any) -> tuple[int, ...]:
    return a.shape if type(a) is np.ndarray else np.shape(a)


def _check_step(Ak: Any, Bk: Any, dk: Any, zeta0: Any, u_prev: Any, ref: Any, n_p: int,
                n_c: int, q_eff: Any, r_eff: Any, s_level: Any, warm: Any, terminal_w: Any,
                bounds: QpBounds | None = None) -> None:
    """The shapes :meth:`MpcQp.solve` needs (its docstring), else ``ValueError`` before
    anything changes: the compiled build indexes its buffers by them. One comparison of
    shapes on the 100 Hz path; the message names the culprit."""
    shape_a = _sh(Ak)
    n = shape_a[0] if len(shape_a) == 2 else -1
    nu = N_INPUT
    if not 1 <= n_c <= n_p:
        raise ValueError(f"horizons: need 1 <= N_c <= N_p, got N_p {n_p}, N_c {n_c}")
    if terminal_w is not None and n_p < 2:
        raise ValueError(f"terminal cost: needs N_p >= 2 (its reference increment), got {n_p}")
    b = bounds
    if (shape_a == (n, n) and _sh(Bk) == (n, nu) and _sh(dk) == (n,) and _sh(zeta0) == (n,)
            and _sh(u_prev) == (nu,) and _sh(ref) == (n_p, 2) and _sh(q_eff) == (2,)
            and _sh(r_eff) == (nu,) and (s_level is None or _sh(s_level) == (nu,))
            and (warm is None or np.size(warm) == n_c * nu)
            and (b is None or (_sh(b.du_max) == _sh(b.u_max) == _sh(b.enabled) == (nu,)
                               and (b.u_min is None or _sh(b.u_min) == (nu,))))):
        return
    want = [(Ak, (n, n), "Ak"), (Bk, (n, nu), "Bk"), (dk, (n,), "dk"), (zeta0, (n,), "zeta0"),
            (u_prev, (nu,), "u_prev"), (ref, (n_p, 2), "ref"), (q_eff, (2,), "q_eff"),
            (r_eff, (nu,), "r_eff"), (s_level, (nu,), "s_level")]
    if b is not None:
        want += [(b.du_max, (nu,), "bounds.du_max"), (b.u_max, (nu,), "bounds.u_max"),
                 (b.enabled, (nu,), "bounds.enabled"), (b.u_min, (nu,), "bounds.u_min")]
    for a, shape, name in want:
        if a is not None and _sh(a) != shape:
            raise ValueError(f"{name}: shape {_sh(a)}, need {shape} (n {n}, N_p {n_p})")
    raise ValueError(f"warm_du_scaled: {np.size(warm)} values, the QP has {n_c * nu} "
                     f"increments (N_c {n_c} x {nu})")


def output_matrix(rows: tuple[int, ...] = OUT_ROWS, n_state: int = N_STATE) -> np.ndarray:
    """C̃ picking ``rows`` of the augmented state of a model of ``n_state`` states, shape
    (len(rows), n_state + 3)."""
    C = np.zeros((len(rows), n_state + N_INPUT))
    C[np.arange(len(rows)), list(rows)] = 1.0
    return C


def matrix_powers(A: np.ndarray, n: int) -> np.ndarray:
    """A^0..A^n stacked, shape (n+1, d, d), by doubling (⌈log2 n⌉ batched matmuls)."""
    d = A.shape[0]
    P = np.empty((n + 1, d, d))
    P[0] = np.eye(d)
    if n == 0:
        return P
    P[1] = A
    have = 1
    while have < n:
        k = min(have, n - have)
        P[have + 1:have + 1 + k] = P[have] @ P[1:1 + k]
        have += k
    return P


def prediction_matrices(Aa: np.ndarray, Ba: np.ndarray, C: np.ndarray, n_p: int, n_c: int,
                        powers: np.ndarray | None = None
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ψ (no·Np, n+3), Θ (no·Np, 3·Nc) of eq. (6) and Γ (no·Np, n+3) of the affine term.

    Rows are ordered step-major (i = 1..Np, then the no outputs of C); columns of Θ step-major
    (j = 0..Nc−1, then the 3 inputs). Y = Ψ ξ + Θ ΔU + Γ d̃. ``powers``: Ã^0..Ã^Np when the
    caller has them (:func:`matrix_powers`), else computed here.
    """
    no = C.shape[0]
    nu = Ba.shape[1]
    P = matrix_powers(Aa, n_p) if powers is None else powers
    CP = C @ P                                   # (Np+1, no, n+3): C Ã^m
    psi = CP[1:].reshape(no * n_p, -1)
    G = CP[:n_p] @ Ba                            # (Np, no, nu): C Ã^m B̃, m = 0..Np−1
    m = np.arange(n_p)[:, None] - np.arange(n_c)[None, :]   # i−1−j
    valid = m >= 0
    blocks = G[np.where(valid, m, 0)] * valid[:, :, None, None]   # (Np, Nc, no, nu)
    theta = blocks.transpose(0, 2, 1, 3).reshape(no * n_p, nu * n_c)
    gamma = np.cumsum(CP[:n_p], axis=0).reshape(no * n_p, -1)
    return psi, theta, gamma


def terminal_rows(Aa: np.ndarray, Ba: np.ndarray, n_p: int, n_c: int,
                  powers: np.ndarray | None = None, n_levels: int = len(OUTPUTS)
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Zx, Zu, Zd) with z_Np + z_ref = Zx ξ + Zu ΔU + Zd d̃: the velocity-form state of
    ``terminal_cost`` at the horizon's end (the lateral rows of ξ_Np − ξ_{Np−1}, then φ and
    Y of ξ_Np; Y alone for ``n_levels`` 1), from the condensed prediction of the lateral rows
    (:func:`prediction_matrices`, eq. (6); ΔU step-major, the input held after N_c); z_ref is
    ``terminal_cost.reference_rows``. ``powers`` as for :func:`prediction_matrices`."""
    n = Aa.shape[0] - Ba.shape[1]
    sel = output_matrix(tuple(lateral_rows(n)), n)
    n_l = sel.shape[0]
    psi, theta, gamma = prediction_matrices(Aa, Ba, sel, n_p, n_c, powers)
    out = list(output_positions(n, n_levels))
    end = slice((n_p - 1) * n_l, n_p * n_l)
    before = slice((n_p - 2) * n_l, (n_p - 1) * n_l)

    def velocity(m: np.ndarray, start: np.ndarray | float) -> np.ndarray:
        # ξ_0 = ξ itself when N_p = 1: its lateral rows for Ψ, nothing for Θ and Γ
        return np.vstack([m[end] - (m[before] if n_p >= 2 else start), m[end][out]])

    return velocity(psi, sel), velocity(theta, 0.0), velocity(gamma, 0.0)


def input_level_cost(n_p: int, n_c: int, D: np.ndarray, s_eff: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(M, w) of the level penalty: u over the planned steps is u(k−1) tiled + M ΔŨ, with
    M (3Nc, 3Nc) the cumulative sum times D, and w (3Nc,) the level weights per planned step,
    the last step's counted N_p − N_c + 1 times (held to the horizon's end). The cost adds
    ΔŨᵀ Mᵀ diag(w) M ΔŨ + 2 u_tᵀ diag(w) M ΔŨ (+ const) for u_t = u(k−1) tiled."""
    cum, hold = _level_structure(n_p, n_c)
    return cum * D[None, :], np.kron(hold, s_eff)


@lru_cache(maxsize=64)
def _level_structure(n_p: int, n_c: int) -> tuple[np.ndarray, np.ndarray]:
    """The horizon-only part of :func:`input_level_cost` (built once per (N_p, N_c), not
    every step; read-only)."""
    cum = np.kron(np.tril(np.ones((n_c, n_c))), np.eye(N_INPUT))
    hold = np.ones(n_c)
    hold[-1] = n_p - n_c + 1
    cum.flags.writeable = hold.flags.writeable = False
    return cum, hold


@dataclass(frozen=True)
class QpBounds:
    """Bounds of eq. (20) in SI units; ``enabled[c]`` False pins input c to zero."""

    du_max: np.ndarray           # (3,) |Δu| per step
    u_max: np.ndarray            # (3,) |u|
    enabled: np.ndarray          # (3,) bool
    vy_max: float                # m/s, hard, from the sideslip bound
    r_max: float                 # rad/s, hard
    band_phi: float              # rad, soft
    band_y: float                # m, soft
    state_bounds: bool = True
    state_bounds_from_step: int = 1   # first prediction step i (1-based) with the hard bounds
    u_min: np.ndarray | None = None   # (3,) lower bound on u; None: −u_max
    #: 0: the v_y and r bounds are hard; c > 0: soft, the slack ε relaxes them by c·bound
    #: (one ε for all soft rows, weight ρ)
    state_softness: float = 0.0

    def lower(self) -> np.ndarray:
        """The lower bound on u (3,): ``u_min``, or −``u_max``."""
        return -self.u_max if self.u_min is None else self.u_min


@dataclass
class QpSolution:
    """Result of one QP solve; ``du``/``u`` are (Nc, 3) SI plans, valid only when ``ok``.
    ``status`` is the solver's own text (recorded in the diagnostics), ``code`` its
    :class:`~fourws_mpc.core.qp_solver.QpStatus`."""

    ok: bool
    status: str
    iterations: int
    du: np.ndarray
    u: np.ndarray
    slack: float
    du_scaled: np.ndarray = field(default_factory=lambda: np.zeros(0))
    code: QpStatus = QpStatus.UNSOLVED


class QpLayout:
    """The fixed structure of the QP of one (Np, Nc) pair: sparsity pattern, row blocks,
    constant parts of A, and the buffers each step refills."""

    def __init__(self, n_p: int, n_c: int) -> None:
        self.n_p, self.n_c = n_p, n_c
        self.pattern, a0 = _structure(n_p, n_c)
        self.nz, self.m = self.pattern.nz, self.pattern.m
        self.ncol = self.nz - 1
        self.uses = 0
        # the dense constraint matrix (rows as in _a_mask): the Δũ box and ε rows are
        # constant, the others refilled every step (condense.constraints)
        self.A = a0.copy()
        self.lo = np.empty(self.m)
        self.hi = np.empty(self.m)
        self._tiled_key: tuple | None = None
        self._tiled: tuple[np.ndarray, ...] = ()

    def tiled(self, b: QpBounds) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(D, enabled, band) repeated over the horizon; cached while unchanged (the input
        levels' bounds, which the grip moves every step, go to ``constraints`` per input)."""
        key = (b.du_max.tobytes(), b.enabled.tobytes(), b.band_phi, b.band_y)
        if key != self._tiled_key:
            self._tiled = (np.tile(b.du_max, self.n_c), np.tile(b.enabled.astype(float),
                                                                 self.n_c),
                           np.tile([b.band_phi, b.band_y], self.n_p))
            self._tiled_key = key
        return self._tiled  # type: ignore[return-value]

    def _a_mask(self) -> np.ndarray:
        """Which entries of A may be non-zero (:func:`_constraint_mask`)."""
        return _constraint_mask(self.n_p, self.n_c)


def _constraint_mask(n_p: int, n_c: int) -> np.ndarray:
    """Which entries of the constraint matrix of (N_p, N_c) may be non-zero, rows in the
    order of :class:`QpLayout` (Δũ box, ε, u bounds, v_y and r above and below, φ and Y
    above and below)."""
    nu = N_INPUT
    ncol = nu * n_c
    # block-triangular pattern of Θ in time (step i reaches increments j ≤ i−1)
    step_mask = (np.arange(n_p)[:, None] >= np.arange(n_c)[None, :])
    th2 = np.repeat(np.repeat(step_mask, 2, axis=0), nu, axis=1)       # 2 rows per step
    cum = np.kron(np.tril(np.ones((n_c, n_c), bool)), np.eye(nu, dtype=bool))
    eye = np.eye(ncol, dtype=bool)
    z = np.zeros
    top = np.hstack([eye, z((ncol, 1), bool)])
    eps_row = np.hstack([z((1, ncol), bool), np.ones((1, 1), bool)])
    ub = np.hstack([cum, z((ncol, 1), bool)])
    # the v_y and r bounds: an upper and a lower row each, with the slack column (its
    # coefficient is 0 while the bounds are hard)
    soft = np.hstack([th2, np.ones((2 * n_p, 1), bool)])
    return np.vstack([top, eps_row, ub, soft, soft, soft, soft])


@lru_cache(maxsize=256)
def _structure(n_p: int, n_c: int) -> tuple[QpPattern, np.ndarray]:
    """The sparsity pattern of (N_p, N_c) and its constraint matrix's constant rows (the rest
    zero), built once per pair in a process (read-only; every :class:`QpLayout` copies the
    matrix): a controller sets up every reachable pair, and a sweep builds one per run."""
    nu = N_INPUT
    ncol = nu * n_c
    nz = ncol + 1
    # P pattern: full upper triangle of the ΔŨ block, plus the slack diagonal
    iu, ju = np.triu_indices(ncol)
    p_rows, p_cols = _csc_order(np.concatenate([iu, [nz - 1]]), np.concatenate([ju, [nz - 1]]))
    mask = _constraint_mask(n_p, n_c)
    a_rows, a_cols = _csc_order(*np.nonzero(mask))
    # rows 0..nz−1 are I: the Δũ box and ε ≥ 0 (bounds on z itself)
    a0 = np.zeros((mask.shape[0], nz))
    a0[:ncol, :ncol] = np.eye(ncol)
    a0[ncol, ncol] = 1.0
    for arr in (p_rows, p_cols, a_rows, a_cols, a0):
        arr.flags.writeable = False
    return QpPattern((n_p, n_c), nz, mask.shape[0], p_rows, p_cols, a_rows, a_cols,
                     simple=nz), a0


def _terminal(terminal_w: np.ndarray | None, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(W, positions of the levelled outputs) for ``condense``; W's size says how many
    output levels z carries (``terminal_cost.levelled_outputs``)."""
    if terminal_w is None:
        return _NO_TERMINAL, output_index(n)
    n_levels = terminal_w.shape[0] - len(lateral_rows(n))
    if not 1 <= n_levels <= len(OUTPUTS):
        raise ValueError(f"terminal weight of size {terminal_w.shape[0]}: a model of {n} states "
                         f"takes {len(lateral_rows(n)) + 1} or {len(lateral_rows(n)) + 2}")
    return terminal_w, output_index(n, n_levels)


@njit(cache=True)
def _build(Ak: np.ndarray, Bk: np.ndarray, dk: np.ndarray, zeta0: np.ndarray,
           u_prev: np.ndarray, ref: np.ndarray, out_rows: np.ndarray, n_c: int, D: np.ndarray,
           q_eff: np.ndarray, r_eff: np.ndarray, s_level: np.ndarray, lat_rows: np.ndarray,
           out_pos: np.ndarray, out_both: np.ndarray, W: np.ndarray, A: np.ndarray,
           lo: np.ndarray, hi: np.ndarray, en: np.ndarray, u_min: np.ndarray,
           u_max: np.ndarray, band: np.ndarray, vy_max: float, r_max: float,
           state_bounds: bool, from_step: int, softness: float
           ) -> tuple[np.ndarray, np.ndarray]:
    """One step's QP in one compiled call: eq. (5) (:func:`augment`), the terminal
    reference (``terminal_cost.reference_rows``), ``condense`` and ``constraints`` (A, lo,
    hi filled in place); returns H and q = [g; 0] (the slack has no linear cost)."""
    n, nu = Bk.shape
    Aa, Ba, da = _augment(Ak, Bk, dk)
    xi = np.empty(n + nu)
    xi[:n] = zeta0
    xi[n:] = u_prev
    z_ref = (reference_rows_compiled(ref, out_both, lat_rows.shape[0], out_pos.shape[0])
             if W.shape[0] > 0 else np.zeros(0))
    H, g, th_out, e_free, th_hard, hard_free = condense(
        Aa, Ba, da, xi, out_rows, n_c, D, ref, q_eff, r_eff, u_prev, s_level, lat_rows,
        out_pos, W, z_ref)
    constraints(A, lo, hi, th_out, e_free, th_hard, hard_free, D, en, u_min, u_max, u_prev,
                band, vy_max, r_max, state_bounds, from_step, softness)
    q = np.zeros(g.shape[0] + 1)
    q[:-1] = g
    return H, q


@njit(cache=True)
def _warm_start(du_scaled: np.ndarray, en: np.ndarray) -> np.ndarray:
    """z₀ = [ΔŨ clipped to the enabled box; ε = 0], the solver's primal warm start."""
    z = np.zeros(du_scaled.shape[0] + 1)
    for k in range(du_scaled.shape[0]):
        z[k] = min(max(du_scaled[k], -en[k]), en[k])
    return z


@njit(cache=True)
def _plan(x: np.ndarray, en: np.ndarray, du_max: np.ndarray, u_prev: np.ndarray,
          u_lo: np.ndarray, u_hi: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(ΔŨ, ΔU, U, ε) of a solution z = [ΔŨ; ε]: Δũ clipped to the enabled box, the
    increments in SI, the levels u(k−1) + Σ Δu clipped to [u_lo, u_hi], ε ≥ 0."""
    nu = du_max.shape[0]
    n_c = (x.shape[0] - 1) // nu
    dus = np.empty((n_c, nu))
    du = np.empty((n_c, nu))
    u = np.empty((n_c, nu))
    total = np.zeros(nu)                     # Σ_{l≤j} Δu_l, then added to u(k−1)
    for j in range(n_c):
        for c in range(nu):
            k = j * nu + c
            dus[j, c] = min(max(x[k], -en[k]), en[k])
            du[j, c] = dus[j, c] * du_max[c]
            total[c] += du[j, c]
            u[j, c] = min(max(u_prev[c] + total[c], u_lo[c]), u_hi[c])
    return dus, du, u, max(x[x.shape[0] - 1], 0.0)


def _csc_order(rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows/cols of a pattern sorted into CSC storage order (column-major)."""
    order = np.lexsort((rows, cols))
    return rows[order], cols[order]


def unconstrained_gain(Ak: np.ndarray, Bk: np.ndarray, dk: np.ndarray, n_p: int, n_c: int,
                       q_eff: np.ndarray, r_eff: np.ndarray, du_max: np.ndarray,
                       enabled: np.ndarray, s_level: np.ndarray | None = None,
                       terminal_w: np.ndarray | None = None) -> np.ndarray:
    """K (3, n+3): the first move u(k) − u(k−1) = −K ξ, ξ = [ζ; u(k−1)], of the QP's
    minimiser without its bounds, on a zero reference: −H⁻¹ ∂g/∂ξ with H and g from
    :func:`~fourws_mpc.core.condense.condense`, the code :meth:`MpcQp.solve` runs. g is
    affine in ξ, so its Jacobian is exact column by column; disabled inputs are left out."""
    n = np.shape(Ak)[0]
    _check_step(Ak, Bk, dk, np.zeros(n), np.zeros(N_INPUT), np.zeros((n_p, 2)), n_p, n_c,
                q_eff, r_eff, s_level, None, terminal_w)
    for name, a in (("du_max", du_max), ("enabled", enabled)):
        if np.shape(a) != (N_INPUT,):
            raise ValueError(f"{name}: shape {np.shape(a)}, need ({N_INPUT},)")
    Aa, Ba, da = augment(Ak, Bk, dk)
    D = np.tile(np.asarray(du_max, dtype=float), n_c)
    ref = np.zeros((n_p, 2))
    W, out = _terminal(terminal_w, n)
    z_ref = _ZERO_U if W.shape[0] == 0 else reference_rows(ref, n, len(out))
    level = _ZERO_U if s_level is None else s_level

    def cost(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        H, g, *_ = condense(Aa, Ba, da, xi, _OUT_ROWS, n_c, D, ref, q_eff, r_eff,
                            np.ascontiguousarray(xi[n:]), level, lateral_rows(n), out, W,
                            z_ref)
        return H, g

    H, g0 = cost(np.zeros(n + N_INPUT))
    G = np.column_stack([cost(e)[1] - g0 for e in np.eye(n + N_INPUT)])
    cols = np.flatnonzero(np.tile(np.asarray(enabled, dtype=bool), n_c))
    full = np.zeros((N_INPUT * n_c, n + N_INPUT))
    full[cols] = -np.linalg.solve(H[np.ix_(cols, cols)], G[cols])     # scaled increments
    return -(full[:N_INPUT] * np.asarray(du_max, dtype=float)[:, None])


class MpcQp:
    """Builds the MPC QP of each step and solves it with the injected solver; keeps one
    :class:`QpLayout` per (Np, Nc) ever used."""

    def __init__(self, settings: QpSettings | None = None, solver: QpSolver | None = None
                 ) -> None:
        self.settings = settings if settings is not None else QpSettings()
        self.solver: QpSolver = solver if solver is not None else DaqpSolver(self.settings)
        self.instances: dict[tuple[int, int], QpLayout] = {}

    def instance(self, n_p: int, n_c: int) -> QpLayout:
        """The layout of (Np, Nc), created (and prepared in the solver) on first use."""
        key = (int(n_p), int(n_c))
        inst = self.instances.get(key)
        if inst is None:
            inst = QpLayout(key[0], key[1])
            self.solver.prepare(inst.pattern)
            self.instances[key] = inst
        return inst

    def solve(
        self,
        Ak: np.ndarray, Bk: np.ndarray, dk: np.ndarray,
        zeta0: np.ndarray, u_prev: np.ndarray,
        ref: np.ndarray, n_p: int, n_c: int,
        q_eff: np.ndarray, r_eff: np.ndarray, rho: float,
        bounds: QpBounds,
        warm_du_scaled: np.ndarray | None = None,
        s_level: np.ndarray | None = None,
        terminal_w: np.ndarray | None = None,
    ) -> QpSolution:
        """Solve one MPC step.

        Ak (n,n), Bk (n,3), dk (n,): model of eq. (4) (n = 6 for eq. (1), more for a model
        with appended states); zeta0 (n,), u_prev (3,) = u(k−1);
        ref (Np, 2): [φ_ref, Y_ref] at i = 1..Np; q_eff (2,) = [q_φ, q_Y] and r_eff (3,) the
        effective weights of the scaled cost; rho the slack weight; warm_du_scaled (Nc, 3)
        optional primal warm start in units of Δu_max; s_level (3,) the effective weights of
        the input-level penalty (``input_level_cost``; None or zeros: the paper's cost);
        terminal_w the weight W of the velocity-form terminal cost z_Npᵀ W z_Np
        (``terminal_cost.terminal_weight``; its size says whether z carries the levels of
        φ and Y or of Y alone; None: the paper's cost, none).
        """
        nu = N_INPUT
        _check_step(Ak, Bk, dk, zeta0, u_prev, ref, n_p, n_c, q_eff, r_eff, s_level,
                    warm_du_scaled, terminal_w, bounds)
        n = Ak.shape[0]
        W, out = _terminal(terminal_w, n)
        inst = self.instance(n_p, n_c)
        D, en, band = inst.tiled(bounds)
        f = _as_float
        lower = bounds.lower()
        H, qvec = _build(f(Ak), f(Bk), f(dk), f(zeta0), f(u_prev), f(ref), _OUT_ROWS, n_c, D,
                         f(q_eff), f(r_eff), _ZERO_U if s_level is None else f(s_level),
                         lateral_rows(n), out, output_index(n), W, inst.A, inst.lo, inst.hi,
                         en, f(lower), f(bounds.u_max), band, float(bounds.vy_max),
                         float(bounds.r_max), bool(bounds.state_bounds),
                         int(bounds.state_bounds_from_step), float(bounds.state_softness))
        warm = None
        if warm_du_scaled is not None:
            warm = _warm_start(f(warm_du_scaled).reshape(-1), en)
        res = self.solver.solve(CondensedQp(inst.pattern, H, 2.0 * rho, qvec, inst.A, inst.lo,
                                            inst.hi), warm)
        inst.uses += 1
        if res.x is None:
            empty = np.zeros((n_c, nu))
            return QpSolution(False, res.detail, res.iterations, empty, empty, 0.0,
                              np.zeros((n_c, nu)), res.status)
        dus, du, u, slack = _plan(f(res.x), en, f(bounds.du_max), f(u_prev), f(lower),
                                  f(bounds.u_max))
        return QpSolution(True, res.detail, res.iterations, du, u, slack, dus, res.status)
