"""Computes the MPC's terminal cost: the LQR cost-to-go after the horizon, in velocity form.

Beyond eq. 16 (``terminal_cost: lqr``; docs/mpc.md, "A terminal cost"). Over the lateral
states x_L (all but v_x and X) and the enabled inputs::

    z = [Δx_L − Δx_L,ref; φ − φ_ref; Y − Y_ref],   z(k+1) = A_z z(k) + B_z Δu(k),
    A_z = [[A_L, 0], [C_L A_L, I]],   B_z = [[B_L], [C_L B_L]]

Δx_L,ref holds the reference's last increments of φ and Y (zero elsewhere). P solves the DARE
of (A_z, B_z, diag(0, Q), R); the weight added at the horizon's end is W = P − diag(0, Q).

With front steer alone (one input) z carries the level of Y only (:func:`levelled_outputs`):
with both levels the modes at 1 of e_φ and e_Y are two eigenvectors one input cannot steer
(PBH). Physically, a front-steered car in steady cornering keeps a heading error equal to its
sideslip, so a cost on the φ level never ends; its increments stay in Δx_L, and the heading
still costs through the Y it moves.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numba import njit

from fourws_mpc.core.model import StateIdx
from fourws_mpc.core.small_linalg import solve_into

#: model states left out of the velocity-form state: the speed (held) and X (drives nothing)
NOT_LATERAL = (StateIdx.VX, StateIdx.X)
#: the outputs of eq. (5), in the order of the QP's reference columns
OUTPUTS = (StateIdx.PHI, StateIdx.Y)


def levelled_outputs(n_inputs: int) -> tuple[int, ...]:
    """The outputs whose levels z carries with ``n_inputs`` enabled inputs: φ and Y with two
    or more, Y alone with one (module docstring); always the last of :data:`OUTPUTS`."""
    if n_inputs < 1:
        raise ValueError("terminal cost: no input enabled")
    return OUTPUTS if n_inputs >= len(OUTPUTS) else OUTPUTS[levels(1)]


def levels(n_levels: int) -> slice:
    """Where the levelled outputs sit in anything ordered as :data:`OUTPUTS` (their weights,
    their reference columns): the last ``n_levels``."""
    return slice(len(OUTPUTS) - n_levels, len(OUTPUTS))


@lru_cache(maxsize=8)
def lateral_rows(n_state: int) -> np.ndarray:
    """Indices of the lateral states of a model with ``n_state`` states (appended states,
    e.g. the steering actuators', are lateral); read-only, built once per model size."""
    rows = np.array([i for i in range(n_state) if i not in NOT_LATERAL])
    rows.flags.writeable = False
    return rows


@lru_cache(maxsize=16)
def output_positions(n_state: int, n_levels: int = len(OUTPUTS)) -> tuple[int, ...]:
    """Where the last ``n_levels`` outputs of ``OUTPUTS`` (φ, Y; or Y alone) sit among
    :func:`lateral_rows`."""
    rows = list(lateral_rows(n_state))
    return tuple(rows.index(o) for o in OUTPUTS[levels(n_levels)])


@njit(cache=True)
def _velocity_form(Ak: np.ndarray, Bk: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                   out: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A_z, B_z) from the lateral ``rows`` of A_k, B_k, the enabled input ``cols`` and the
    positions ``out`` of the levelled outputs among the rows (:func:`velocity_form`)."""
    n_l, n_e, n_in = rows.shape[0], out.shape[0], cols.shape[0]
    A_z = np.zeros((n_l + n_e, n_l + n_e))
    B_z = np.empty((n_l + n_e, n_in))
    for i in range(n_l):
        for j in range(n_l):
            A_z[i, j] = Ak[rows[i], rows[j]]
        for j in range(n_in):
            B_z[i, j] = Bk[rows[i], cols[j]]
    for e in range(n_e):
        A_z[n_l + e, :n_l] = A_z[out[e], :n_l]
        A_z[n_l + e, n_l + e] = 1.0
        B_z[n_l + e] = B_z[out[e]]
    return A_z, B_z


@lru_cache(maxsize=16)
def output_index(n_state: int, n_levels: int = len(OUTPUTS)) -> np.ndarray:
    """:func:`output_positions` as a read-only index array (what the compiled kernels take)."""
    pos = np.array(output_positions(n_state, n_levels), dtype=np.int64)
    pos.flags.writeable = False
    return pos


def _indices(n_state: int, enabled: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return _indices_of(n_state, np.asarray(enabled, dtype=bool).tobytes())


@lru_cache(maxsize=32)
def _indices_of(n_state: int, enabled: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    cols = np.flatnonzero(np.frombuffer(enabled, dtype=bool))
    cols.flags.writeable = False
    return lateral_rows(n_state), cols, output_index(n_state,
                                                     len(levelled_outputs(cols.shape[0])))


def velocity_form(Ak: np.ndarray, Bk: np.ndarray, enabled: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(A_z, B_z) of the velocity-form lateral model (module docstring); B_z has a column per
    enabled input, z the levels of :func:`levelled_outputs` of their number."""
    f = np.ascontiguousarray
    return _velocity_form(f(Ak, dtype=float), f(Bk, dtype=float),
                          *_indices(Ak.shape[0], enabled))


@njit(cache=True)
def _terminal_weight(Ak: np.ndarray, Bk: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                     out: np.ndarray, q_lev: np.ndarray, r_en: np.ndarray, rtol: float,
                     max_steps: int) -> tuple[np.ndarray, bool]:
    """(W, converged) of :func:`terminal_weight`, compiled; ``q_lev`` the weights of the
    levelled outputs."""
    A_z, B_z = _velocity_form(Ak, Bk, rows, cols, out)
    n_z, n_e = A_z.shape[0], out.shape[0]
    Q_z = np.zeros((n_z, n_z))
    for e in range(n_e):
        Q_z[n_z - n_e + e, n_z - n_e + e] = q_lev[e]
    P, ok = _sda(A_z, B_z, Q_z, np.diag(r_en), rtol, max_steps)
    W = P - Q_z
    return 0.5 * (W + W.T), ok


def terminal_weight(Ak: np.ndarray, Bk: np.ndarray, enabled: np.ndarray,
                    q_eff: np.ndarray, r_eff: np.ndarray) -> np.ndarray:
    """W = P − Q_z on z = [Δx_L; φ − φ_ref; Y − Y_ref] at the horizon's end (Y − Y_ref alone
    with front steer alone), P the DARE's stabilising solution on (A_z, B_z, Q_z = diag(0, Q),
    R) (:func:`solve_dare`).

    Ak (n, n), Bk (n, 3): the discrete model of the step; enabled (3,) bool: the inputs the
    preset uses; q_eff (2,) = [q_φ, q_Y], r_eff (3,): the effective weights the QP uses (SI
    units). Raises ``np.linalg.LinAlgError`` or ``ValueError`` where the DARE has no
    stabilising solution (the caller then solves without a terminal cost).
    """
    return TerminalWeight()(Ak, Bk, enabled, q_eff, r_eff)


#: a terminal weight is reused while A_k, each column of B_k and each weight stay within this
#: relative change (max-norm) of those it was solved for, the enabled inputs the same; the
#: cost-to-go then equals a full solve to 1e-9 relative (measured: 2.4 times the change;
#: tests/unit/test_mpc_terminal_cost.py)
REUSE_RTOL = 1e-10


class TerminalWeight:
    """:func:`terminal_weight` that reuses its last W while the data stay within
    :data:`REUSE_RTOL` (a car on a steady straight); ``solves``, ``reuses`` count both."""

    def __init__(self) -> None:
        self._last: tuple | None = None
        self.solves = 0
        self.reuses = 0

    def __call__(self, Ak: np.ndarray, Bk: np.ndarray, enabled: np.ndarray,
                 q_eff: np.ndarray, r_eff: np.ndarray) -> np.ndarray:
        """W of :func:`terminal_weight`, with its errors; a failed solve is not kept."""
        rows, cols, out = _indices(Ak.shape[0], enabled)
        f = np.ascontiguousarray
        q = np.asarray(q_eff, dtype=float)
        data = (f(Ak, dtype=float), f(Bk, dtype=float), f(q[levels(out.shape[0])]),
                f(np.asarray(r_eff, dtype=float)[cols]))
        last = self._last
        if (last is not None and last[0] is cols and last[1].shape == data[0].shape
                and _within(*data, *last[1:5], REUSE_RTOL)):
            self.reuses += 1
            return last[5]
        self._last = None
        W, ok = _terminal_weight(data[0], data[1], rows, cols, out, data[2], data[3],
                                 DARE_RTOL, DARE_MAX_STEPS)
        if not ok:
            raise np.linalg.LinAlgError(_NO_SOLUTION)
        W.flags.writeable = False
        self._last = (cols, *(a.copy() for a in data), W)
        self.solves += 1
        return W


@njit(cache=True)
def _changed(x: np.ndarray, ref: np.ndarray) -> float:
    """max |x − ref| / max |ref| (0 for two zero blocks; inf for a non-finite x)."""
    big, diff = 0.0, 0.0
    for i in range(x.shape[0]):
        if not np.isfinite(x[i]):
            return np.inf
        big = max(big, abs(ref[i]))
        diff = max(diff, abs(x[i] - ref[i]))
    if diff == 0.0:
        return 0.0
    return diff / big if big > 0.0 else np.inf


@njit(cache=True)
def _within(Ak: np.ndarray, Bk: np.ndarray, q: np.ndarray, r: np.ndarray,
            Ak0: np.ndarray, Bk0: np.ndarray, q0: np.ndarray, r0: np.ndarray, rtol: float
            ) -> bool:
    """The data within ``rtol`` of (Ak0, …): A_k as one block, B_k per column, each weight
    on its own."""
    if _changed(Ak.ravel(), Ak0.ravel()) > rtol:
        return False
    for j in range(Bk.shape[1]):
        if _changed(np.ascontiguousarray(Bk[:, j]), np.ascontiguousarray(Bk0[:, j])) > rtol:
            return False
    for i in range(q.shape[0]):
        if _changed(q[i:i + 1], q0[i:i + 1]) > rtol:
            return False
    for i in range(r.shape[0]):
        if _changed(r[i:i + 1], r0[i:i + 1]) > rtol:
            return False
    return True


#: the doubling's stopping rule: relative change of P in the 1-norm (a shortcut that trusted
#: the quadratic convergence earlier, one doubling fewer, stopped early on slow modes that Q
#: barely weighs; measured, and not kept)
DARE_RTOL = 1e-13
#: doubling steps before giving up (the error contracts like ρ_cl^(2^k): 9 suffice here)
DARE_MAX_STEPS = 40
_NO_SOLUTION = ("terminal cost: the DARE has no stabilising solution (the doubling did not "
                f"converge in {DARE_MAX_STEPS} steps)")


@njit(cache=True)
def _change_norm1(M: np.ndarray, M0: np.ndarray) -> tuple[float, float]:
    """(‖M − M0‖₁, ‖M‖₁), the largest column sums; the first is not finite if M is not."""
    change, size = 0.0, 0.0
    for j in range(M.shape[1]):
        cd, cs = 0.0, 0.0
        for i in range(M.shape[0]):
            cd += abs(M[i, j] - M0[i, j])
            cs += abs(M[i, j])
        if not np.isfinite(cs):
            return np.inf, np.inf
        change, size = max(change, cd), max(size, cs)
    return change, size


@njit(cache=True)
def _sda(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray, rtol: float,
         max_steps: int) -> tuple[np.ndarray, bool]:
    """The doubling of :func:`solve_dare`, compiled: (P, converged). Every product and solve
    goes into a buffer kept across the doublings (the solve: ``small_linalg.solve_into``)."""
    n = A.shape[0]
    Rf = R.copy()
    RiBt = np.ascontiguousarray(B.T)
    if not solve_into(Rf, RiBt):                          # R⁻¹ Bᵀ
        return Q.copy(), False
    G = np.empty((n, n))
    np.dot(B, RiBt, G)
    H = Q.copy()
    Ak = A.copy()
    W = np.empty((n, n))
    rhs = np.empty((n, 2 * n))
    Va, Vg, AkT = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    t1, t2, H_next = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    for _ in range(max_steps):
        np.dot(G, H, W)                                   # W = I + G_k H_k
        for i in range(n):
            W[i, i] += 1.0
        rhs[:, :n] = Ak
        rhs[:, n:] = G
        if not solve_into(W, rhs):                        # W⁻¹ [A_k, G_k]
            return H, False
        Va[:, :] = rhs[:, :n]
        Vg[:, :] = rhs[:, n:]
        AkT[:, :] = Ak.T
        np.dot(H, Va, t1)                                 # H_k+1 = H_k + A_kᵀ H_k W⁻¹ A_k
        np.dot(AkT, t1, H_next)
        H_next += H
        np.dot(Vg, AkT, t1)                               # G_k+1 = G_k + A_k W⁻¹ G_k A_kᵀ
        np.dot(Ak, t1, t2)
        G += t2
        np.dot(Ak, Va, t1)                                # A_k+1 = A_k W⁻¹ A_k
        Ak[:, :] = t1
        change, size = _change_norm1(H_next, H)
        if not np.isfinite(change):
            return H_next, False
        if change <= rtol * size:
            return 0.5 * (H_next + H_next.T), True
        H[:, :] = H_next
    return H, False


def solve_dare(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray) -> np.ndarray:
    """The stabilising solution P of AᵀPA − P − AᵀPB(R + BᵀPB)⁻¹BᵀPA + Q = 0, R > 0.

    Structure-preserving doubling (SDA; Chu, Fan, Lin & Wang, Int. J. Control 77, 2004;
    convergence: Lin & Xu, SIAM J. Matrix Anal. Appl. 28, 2006): with G = BR⁻¹Bᵀ, H = Q,

        W = I + G_k H_k,  A_{k+1} = A_k W⁻¹ A_k,
        G_{k+1} = G_k + A_k W⁻¹ G_k A_kᵀ,  H_{k+1} = H_k + A_kᵀ H_k W⁻¹ A_k,

    H_k → P quadratically (the error like ρ(A − BK)^(2^k)), compiled (numba). It is used
    instead of ``scipy.linalg.solve_discrete_are`` (the QZ method; the unit test's oracle)
    because the DARE is solved every control step. Raises ``np.linalg.LinAlgError`` when it
    does not converge (no stabilising solution: (A, B) not stabilisable or (Q, A) with an
    unobservable mode on the unit circle) or meets a singular W.
    """
    f = np.ascontiguousarray
    P, ok = _sda(f(A, dtype=float), f(B, dtype=float), f(Q, dtype=float), f(R, dtype=float),
                 DARE_RTOL, DARE_MAX_STEPS)
    if not ok:
        raise np.linalg.LinAlgError(_NO_SOLUTION)
    return P


def reference_rows(ref: np.ndarray, n_state: int, n_levels: int = len(OUTPUTS)
                   ) -> np.ndarray:
    """z_ref: the reference's part of z at the horizon's end (module docstring) for a model
    of ``n_state`` states, from ``ref`` (N_p, 2) = [φ_ref, Y_ref] at i = 1..N_p: the last
    step's increments of φ_ref and Y_ref in the Δx rows of φ and Y, then the levels of the
    last ``n_levels`` outputs (φ_ref and Y_ref, or Y_ref alone)."""
    return reference_rows_compiled(np.ascontiguousarray(ref, dtype=float),
                                   output_index(n_state), len(lateral_rows(n_state)), n_levels)


@njit(cache=True)
def reference_rows_compiled(ref: np.ndarray, out_both: np.ndarray, n_l: int, n_levels: int
                            ) -> np.ndarray:
    """:func:`reference_rows` from the positions ``out_both`` of φ and Y among the ``n_l``
    lateral rows (:func:`output_index` with both levels), callable from compiled code."""
    n_p, n_o = ref.shape
    z = np.zeros(n_l + n_levels)
    for o in range(n_o):
        prev = ref[n_p - 2, o] if n_p >= 2 else 0.0
        z[out_both[o]] = ref[n_p - 1, o] - prev
    for e in range(n_levels):
        z[n_l + e] = ref[n_p - 1, n_o - n_levels + e]
    return z


def terminal_terms(W: np.ndarray, Zs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(2 Zsᵀ W Zs, 2 Zsᵀ W): the terminal cost's Hessian and the map from the free
    terminal error to its gradient, in the QP's scaled increments (Zs = Zu D), in the
    convention ½ zᵀ H z + gᵀ z of ``qp``."""
    cross = 2.0 * (Zs.T @ W)
    return cross @ Zs, cross
