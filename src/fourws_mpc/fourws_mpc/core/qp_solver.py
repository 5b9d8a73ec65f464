"""Defines the solver seam: a condensed QP, a solver protocol, a status enum, and the solvers.

The MPC (``qp.MpcQp``) condenses eq. (16)-(20) into one dense QP in z = [ΔŨ; ε]
(docs/mpc.md, "Solver")::

    minimise   ½ zᵀ P z + qᵀ z,   P = blockdiag(H, 2ρ)
    subject to lo ≤ A z ≤ hi

(:class:`CondensedQp`) and hands it to a :class:`QpSolver`. A solver returns a
:class:`QpResult` with a solver-independent :class:`QpStatus`; only a solution the solver
calls optimal (``SOLVED``, and ``SOLVED_INACCURATE`` when ``accept_inaccurate``) with a finite
z is trusted (:func:`trusted`): anything else is a failed solve, and the MPC falls back.
Data a solver's validation would refuse (non-finite entries, lo > hi) are never handed to it:
:func:`invalid_data` says why, and the step is a failed solve with status ``INVALID_DATA``.

Solvers are chosen by name (:data:`QP_SOLVERS`, parameter ``qp_solver``). :class:`OsqpSolver`
keeps one warm-started OSQP instance per sparsity pattern (one per (N_p, N_c)) and updates
P, q, A, l, u in place (explicit zeros kept), as osqp-python recommends over a rebuild.
:class:`DaqpSolver` hands the dense QP to DAQP (Arnström, Bemporad, Axehill, "A dual
active-set solver for embedded quadratic programming using recursive LDLᵀ updates", IEEE
TAC 2022), cold-started: its answer is the exact active-set solution, where OSQP's meets
``eps_abs``/``eps_rel``.
"""

from __future__ import annotations

import enum
import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numba import njit

from fourws_common.params import choose

#: OSQP's infinity, ``osqp.constant("OSQP_INFTY")`` (a unit test checks); osqp and
#: scipy.sparse are imported by the OSQP solver only: a DAQP controller starts without them
OSQP_INFTY = 1e30
_INF = np.inf


class QpStatus(enum.Enum):
    """Outcome of one solve, whatever the solver."""

    SOLVED = "solved"
    SOLVED_INACCURATE = "solved inaccurate"
    PRIMAL_INFEASIBLE = "primal infeasible"
    DUAL_INFEASIBLE = "dual infeasible"
    MAX_ITER_REACHED = "maximum iterations reached"
    TIME_LIMIT_REACHED = "time limit reached"
    NON_CONVEX = "problem non convex"
    INTERRUPTED = "interrupted"
    UNSOLVED = "unsolved"
    INVALID_DATA = "invalid data"


@functools.cache
def _osqp_statuses() -> dict[int, QpStatus]:
    """OSQP's ``info.status_val`` -> :class:`QpStatus`, through ``osqp.SolverStatus``
    (built at the first OSQP solve, so a DAQP controller never imports osqp)."""
    import osqp

    st = osqp.SolverStatus
    table = {
        st.OSQP_SOLVED: QpStatus.SOLVED,
        st.OSQP_SOLVED_INACCURATE: QpStatus.SOLVED_INACCURATE,
        st.OSQP_PRIMAL_INFEASIBLE: QpStatus.PRIMAL_INFEASIBLE,
        st.OSQP_PRIMAL_INFEASIBLE_INACCURATE: QpStatus.PRIMAL_INFEASIBLE,
        st.OSQP_DUAL_INFEASIBLE: QpStatus.DUAL_INFEASIBLE,
        st.OSQP_DUAL_INFEASIBLE_INACCURATE: QpStatus.DUAL_INFEASIBLE,
        st.OSQP_MAX_ITER_REACHED: QpStatus.MAX_ITER_REACHED,
        st.OSQP_TIME_LIMIT_REACHED: QpStatus.TIME_LIMIT_REACHED,
        st.OSQP_NON_CVX: QpStatus.NON_CONVEX,
        st.OSQP_SIGINT: QpStatus.INTERRUPTED,
        st.OSQP_UNSOLVED: QpStatus.UNSOLVED,
    }
    return {int(k.value): v for k, v in table.items()}


def osqp_status(status_val: int) -> QpStatus:
    """:class:`QpStatus` of an OSQP ``info.status_val`` (an unknown value: UNSOLVED)."""
    return _osqp_statuses().get(int(status_val), QpStatus.UNSOLVED)


@dataclass(frozen=True)
class QpSettings:
    """Settings shared by every solve (OSQP's names; a dense solver uses what applies)."""

    eps_abs: float = 1e-4
    eps_rel: float = 1e-4
    max_iter: int = 4000
    polishing: bool = False
    accept_inaccurate: bool = False
    check_termination: int = 5


@dataclass(frozen=True)
class QpPattern:
    """Which entries of P's upper triangle and of A may be non-zero, for one (N_p, N_c):
    rows and columns in CSC storage order. ``key`` names the pattern (N_p, N_c)."""

    key: tuple[int, int]
    nz: int                      # variables: 3 N_c increments and the slack
    m: int                       # constraint rows
    p_rows: np.ndarray
    p_cols: np.ndarray
    a_rows: np.ndarray
    a_cols: np.ndarray
    simple: int = 0              # leading rows of A that are I (nz): bounds on z itself


@dataclass
class CondensedQp:
    """One condensed QP (module docstring); ``H`` (nz−1, nz−1) is the increments' Hessian
    (symmetric to rounding: a solver reads its upper triangle), ``slack_hessian`` = 2ρ the
    slack's, ``A`` (m, nz) dense with zeros off the pattern."""

    pattern: QpPattern
    H: np.ndarray
    slack_hessian: float
    q: np.ndarray
    A: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


@dataclass(frozen=True)
class QpResult:
    """What a solver returns: status, its own status text, z (None unless finite and
    trusted), iterations, and ``ok`` = the solution may be used."""

    status: QpStatus
    detail: str
    x: np.ndarray | None
    iterations: int

    @property
    def ok(self) -> bool:
        """A trusted solution (:func:`trusted`) is present."""
        return self.x is not None


class QpSolver(Protocol):
    """What the MPC needs of a QP solver."""

    def prepare(self, pattern: QpPattern) -> None:
        """Set up for this pattern ahead of the control loop (may do nothing)."""

    def solve(self, qp: CondensedQp, warm_x: np.ndarray | None) -> QpResult:
        """Solve ``qp``; ``warm_x`` (nz,) an optional primal warm start."""

    def reset(self) -> None:
        """Forget everything learnt between solves (warm starts, adapted step sizes), so the
        next solves equal those of a new solver."""


def trusted(status: QpStatus, x: np.ndarray | None, accept_inaccurate: bool) -> bool:
    """The one status rule: optimal (or optimal-inaccurate when accepted) and finite."""
    good = status is QpStatus.SOLVED or (accept_inaccurate
                                         and status is QpStatus.SOLVED_INACCURATE)
    return bool(good and x is not None and np.isfinite(x).all())


@njit(cache=True)
def _invalid_code(q: np.ndarray, P: np.ndarray, A: np.ndarray, lo: np.ndarray,
                  hi: np.ndarray, infty: float) -> int:
    """0 valid, 1-3 a non-finite q, P, A entry, 4 bad bounds, 5 l > u (:func:`invalid_data`,
    one compiled pass)."""
    for code, v in ((1, q), (2, P), (3, A)):
        for x in v:
            if not np.isfinite(x):
                return code
    for k in range(lo.shape[0]):
        if np.isnan(lo[k]) or np.isnan(hi[k]) or lo[k] == np.inf or hi[k] == -np.inf:
            return 4
    for k in range(lo.shape[0]):
        if max(lo[k], -infty) > min(hi[k], infty):
            return 5
    return 0


_INVALID = ("", "non-finite q", "non-finite P", "non-finite A", "bad bounds", "l > u")


def invalid_data(q: np.ndarray, lo: np.ndarray, hi: np.ndarray, P: np.ndarray,
                 A: np.ndarray) -> str:
    """Why a solver's data validation would reject this QP ("" if it would not): a
    non-finite q, P or A entry, a NaN or +inf lower / -inf upper bound, or l > u (the bounds
    clipped to ±OSQP_INFTY first, as OSQP's wrapper does)."""
    f = np.ascontiguousarray
    return _INVALID[_invalid_code(f(q, dtype=float).ravel(), f(P, dtype=float).ravel(),
                                  f(A, dtype=float).ravel(), f(lo, dtype=float),
                                  f(hi, dtype=float), OSQP_INFTY)]


def _csc_ones(rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> Any:
    """A CSC matrix of ones on a pattern given in CSC storage order."""
    indptr = np.concatenate([[0], np.cumsum(np.bincount(cols, minlength=shape[1]))])
    import scipy.sparse as sp

    return sp.csc_matrix((np.ones(len(rows)), rows.astype(np.int64), indptr), shape=shape)


class OsqpSolver:
    """OSQP (ADMM, sparse), one warm-started instance per :class:`QpPattern`."""

    name = "osqp"

    def __init__(self, settings: QpSettings) -> None:
        self.settings = settings
        import osqp  # noqa: F401 - fail at construction, naming the missing package

        self.instances: dict[tuple[int, int], Any] = {}

    def prepare(self, pattern: QpPattern) -> None:
        """Set up the OSQP instance of ``pattern`` (unit data on the full pattern)."""
        if pattern.key in self.instances:
            return
        import osqp

        s = self.settings
        solver = osqp.OSQP()
        solver.setup(
            _csc_ones(pattern.p_rows, pattern.p_cols, (pattern.nz, pattern.nz)),
            np.zeros(pattern.nz),
            _csc_ones(pattern.a_rows, pattern.a_cols, (pattern.m, pattern.nz)),
            -np.ones(pattern.m), np.ones(pattern.m),
            eps_abs=s.eps_abs, eps_rel=s.eps_rel, max_iter=s.max_iter,
            polishing=s.polishing, warm_starting=True, verbose=False,
            check_termination=s.check_termination,
        )
        self.instances[pattern.key] = solver

    def reset(self) -> None:
        """Drop every instance (their adapted ρ and duals); patterns are set up again."""
        self.instances.clear()

    def solve(self, qp: CondensedQp, warm_x: np.ndarray | None) -> QpResult:
        """Update the pattern's instance in place, warm-start, solve. A failed solve resets
        the instance's warm start to zero, so the next step does not start from it."""
        pat = qp.pattern
        Px = np.empty(len(pat.p_rows))
        Px[:-1] = qp.H[pat.p_rows[:-1], pat.p_cols[:-1]]
        Px[-1] = qp.slack_hessian
        Ax = qp.A[pat.a_rows, pat.a_cols]
        bad = invalid_data(qp.q, qp.lo, qp.hi, Px, Ax)
        if bad:
            # OSQP would refuse the update (its wrapper ignores that) and solve the previous
            # step's data: never hand it over.
            return QpResult(QpStatus.INVALID_DATA, f"invalid data: {bad}", None, 0)
        self.prepare(pat)
        s = self.instances[pat.key]
        s.update(q=qp.q, l=qp.lo, u=qp.hi, Px=Px, Ax=Ax)
        if warm_x is not None:
            s.warm_start(x=warm_x)
        res = s.solve(raise_error=False)
        status = osqp_status(res.info.status_val)
        x = res.x
        if not trusted(status, x, self.settings.accept_inaccurate):
            s.warm_start(x=np.zeros(pat.nz), y=np.zeros(pat.m))
            x = None
        return QpResult(status, str(res.info.status), x, int(res.info.iter))


#: DAQP's exit flags (daqp's ``exitflag``) -> :class:`QpStatus`
_DAQP_STATUS = {1: QpStatus.SOLVED, 2: QpStatus.SOLVED, -1: QpStatus.PRIMAL_INFEASIBLE,
                -2: QpStatus.UNSOLVED, -3: QpStatus.DUAL_INFEASIBLE,
                -4: QpStatus.MAX_ITER_REACHED, -5: QpStatus.NON_CONVEX,
                -6: QpStatus.UNSOLVED}
_DAQP_TEXT = {1: "optimal", 2: "soft optimal", -1: "infeasible", -2: "cycling",
              -3: "unbounded", -4: "iteration limit", -5: "nonconvex problem",
              -6: "initial point infeasible"}
#: DAQP's infinity: a bound beyond it is absent
DAQP_INF = 1e30


class DaqpSolver:
    """DAQP (dense dual active set), cold-started on every QP (module docstring).

    P = blockdiag(H, 2ρ) is dense and positive definite (the increment weights and ρ are
    positive), as a dual active-set method needs. ``max_iter`` is DAQP's iteration limit;
    the ADMM tolerances do not apply."""

    name = "daqp"

    def __init__(self, settings: QpSettings) -> None:
        import daqp  # noqa: F401 - fail at construction, naming the missing package

        self.settings = settings

    def prepare(self, pattern: QpPattern) -> None:
        """Nothing to set up: each QP is solved from its dense data."""

    def reset(self) -> None:
        """Nothing is kept between solves."""

    def solve(self, qp: CondensedQp, warm_x: np.ndarray | None) -> QpResult:
        import daqp

        f = np.ascontiguousarray
        # the pattern's leading identity rows go to DAQP as simple bounds on z (bounds
        # longer than A's rows: the first ones bound z), which it handles without a row
        simple = qp.pattern.simple if qp.pattern.simple == qp.pattern.nz else 0
        q, A = f(qp.q, dtype=float), f(qp.A, dtype=float)
        P, lo, hi, sense, code = _daqp_data(
            f(qp.H, dtype=float), float(qp.slack_hessian), q, A, f(qp.lo, dtype=float),
            f(qp.hi, dtype=float), OSQP_INFTY, DAQP_INF)
        A = A[simple:]                      # rows of a C-ordered matrix: a view, no copy
        if code:
            return QpResult(QpStatus.INVALID_DATA, f"invalid data: {_INVALID[code]}", None, 0)
        x, _fval, flag, info = daqp.solve(P, q, A, hi, lo, sense,
                                          iter_limit=self.settings.max_iter)
        status = _DAQP_STATUS.get(int(flag), QpStatus.UNSOLVED)
        x = np.asarray(x, dtype=float) if x is not None else None
        if not trusted(status, x, self.settings.accept_inaccurate):
            x = None
        iters = int(info.get("iterations", 0)) if isinstance(info, dict) else 0
        return QpResult(status, _DAQP_TEXT.get(int(flag), f"exit flag {flag}"), x, iters)


@njit(cache=True)
def _daqp_data(H: np.ndarray, slack: float, q: np.ndarray, A: np.ndarray, lo: np.ndarray,
               hi: np.ndarray, infty: float, daqp_inf: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """DAQP's data in one compiled pass: P = blockdiag(½ (H + Hᵀ), slack), the bounds
    clamped to ±``daqp_inf``, the constraint senses (0: an inequality) and
    :func:`_invalid_code` of the QP (0: valid)."""
    nz = H.shape[0] + 1
    P = np.zeros((nz, nz))
    for i in range(nz - 1):
        for j in range(nz - 1):
            P[i, j] = 0.5 * (H[i, j] + H[j, i])
    P[nz - 1, nz - 1] = slack
    code = _invalid_code(q, P.ravel(), A.ravel(), lo, hi, infty)
    return (P, np.maximum(lo, -daqp_inf), np.minimum(hi, daqp_inf),
            np.zeros(lo.shape[0], dtype=np.int32), code)


#: solver name (parameter ``qp_solver``) -> factory
QP_SOLVERS: dict[str, Callable[[QpSettings], QpSolver]] = {"osqp": OsqpSolver,
                                                            "daqp": DaqpSolver}


def make_qp_solver(name: str, settings: QpSettings) -> QpSolver:
    """The solver called ``name`` (:data:`QP_SOLVERS`)."""
    return choose(QP_SOLVERS, name, "qp_solver")(settings)
