"""Holds the OSQP workspace of ``optimal_bounded``'s final split (``allocation``, module docstring).

With the achievable side sums (S_L*, S_R*) fixed by the priority stage, the split that
minimises the tyre usage Σ (T_i / (r μ_i F_zi))² (eq. 26) under |T_i| ≤ b_i is a 4-variable
QP with two equalities (eq. 27 rewritten as eq. 28's side sums) and four boxes. It is set up
once and updated each call (P, l, u; warm start, polishing), as osqp-python recommends
(docs/lower-layer.md, "Allocation").
"""

from __future__ import annotations

import math

import numpy as np

from fourws_common.wheels import Wheel

#: ``info.status_polish`` of a successful polish (OSQP exports no enum for it: 1 success,
#: 0 unperformed, -1 unsuccessful)
OSQP_POLISH_SUCCESSFUL = 1
#: largest side-sum residual after polishing, relative to T_motor,max, that is moved onto a
#: wheel rather than refused
_RESIDUAL_TOL = 1.0e-6

_FL, _FR, _RL, _RR = Wheel.FL, Wheel.FR, Wheel.RL, Wheel.RR


def clip_scalar(v: float, lo: float, hi: float) -> float:
    """v clipped to [lo, hi] (lo ≤ hi), for Python floats."""
    return lo if v < lo else hi if v > hi else v


class BoundedQp:
    """OSQP workspace for the final split of :func:`optimal_bounded` (set up once).

    Variables x_i = T_i / T_motor,max; objective ½ Σ p_i x_i², p_i = (c_max/c_i)²
    (∝ 1/(μ_i F_zi)², scaled so min p_i = 1); rows: the side sums x_fl + x_rl = S_L*/T_max
    and x_fr + x_rr = S_R*/T_max (eq. 27 rewritten as in eq. 28), then |x_i| ≤ b_i/T_max.
    A side whose sum is at the edge of its range (|S*| = b_f + b_r) has a single feasible
    point, both wheels at their bounds; it is fixed through l = u on its bound rows and its
    sum row is freed, so the QP handed to OSQP is never degenerate (polishing then finds the
    exact active set). With both sides fixed OSQP is not called.
    """

    def __init__(self) -> None:
        import osqp
        import scipy.sparse as sp

        self._status = osqp.SolverStatus

        p = sp.triu(sp.identity(4, format="csc")).tocsc()
        a = sp.csc_matrix(np.vstack([[1.0, 0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 1.0], np.eye(4)]))
        self._l = np.zeros(6)
        self._u = np.zeros(6)
        self._px = np.ones(4)
        self._solver = osqp.OSQP()
        self._solver.setup(p, np.zeros(4), a, self._l, self._u, verbose=False,
                           polishing=True, warm_starting=True, eps_abs=1.0e-6,
                           eps_rel=1.0e-6, max_iter=4000, polish_refine_iter=5,
                           adaptive_rho_interval=10)
        self.last_status = ""

    def solve(self, s_left: float, s_right: float, cap: list[float], bounds: list[float],
              scale: float) -> list[float] | None:
        """Torques (N·m) with side sums exactly (s_left, s_right), or None on failure.

        Needs |s_left| ≤ b_fl + b_rl and |s_right| ≤ b_fr + b_rr. ADMM runs to 1e-6 and
        polishing (required; None otherwise) recovers the exact active-set solution. The
        result is clipped to the bounds and its side-sum residual (~1e-13 after polishing;
        > 1e-6 T_max is refused) moved onto the wheel of the side with the most room, so
        the equalities hold to rounding.
        """
        c_max = max(cap)
        px = self._px
        for i in range(4):
            px[i] = (c_max / cap[i]) ** 2 if cap[i] > 0.0 else 1.0
        px /= px.min()
        l, u = self._l, self._u
        fixed = [False, False]
        x_fixed = [0.0] * 4
        for k, (front, rear, s) in enumerate(((_FL, _RL, s_left), (_FR, _RR, s_right))):
            b_side = bounds[front] + bounds[rear]
            u[2 + front] = bounds[front] / scale
            l[2 + front] = -u[2 + front]
            u[2 + rear] = bounds[rear] / scale
            l[2 + rear] = -u[2 + rear]
            if abs(s) >= b_side * (1.0 - 1.0e-12):
                fixed[k] = True
                x_fixed[front] = math.copysign(bounds[front], s)
                x_fixed[rear] = math.copysign(bounds[rear], s)
                l[2 + front] = u[2 + front] = x_fixed[front] / scale
                l[2 + rear] = u[2 + rear] = x_fixed[rear] / scale
                l[k], u[k] = -math.inf, math.inf
            else:
                l[k] = u[k] = s / scale
        if fixed[0] and fixed[1]:
            self.last_status = "fixed"
            return x_fixed
        if s_left == 0.0 and s_right == 0.0:
            self.last_status = "zero"  # the unique optimum; OSQP's polish reports failure here
            return [0.0] * 4
        self._solver.update(Px=px, l=l, u=u)
        res = self._solver.solve(raise_error=False)
        self.last_status = str(res.info.status)
        solved = self._status(res.info.status_val) is self._status.OSQP_SOLVED
        if not solved or res.info.status_polish != OSQP_POLISH_SUCCESSFUL or res.x is None:
            return None
        x = [clip_scalar(float(res.x[i]) * scale, -bounds[i], bounds[i]) for i in range(4)]
        if not all(math.isfinite(v) for v in x):
            return None
        for k, (front, rear, s) in enumerate(((_FL, _RL, s_left), (_FR, _RR, s_right))):
            if fixed[k]:
                x[front], x[rear] = x_fixed[front], x_fixed[rear]
                continue
            delta = s - (x[front] + x[rear])
            if abs(delta) > _RESIDUAL_TOL * scale:
                return None
            if delta == 0.0:
                continue
            room_f = bounds[front] - x[front] if delta > 0.0 else x[front] + bounds[front]
            room_r = bounds[rear] - x[rear] if delta > 0.0 else x[rear] + bounds[rear]
            i = front if room_f >= room_r else rear
            if abs(delta) > max(room_f, room_r):
                return None
            x[i] += delta
        return x
