"""Extends the relaxation model by saturating axle forces: the friction-aware prediction model.

Beyond the paper (docs/mpc.md, "Friction-aware prediction"). The state and input are those of
``relaxation_model``; each axle's lateral force is the Magic Formula of ``axle_tyre`` on its
transient slip α', summed over its two tyres, instead of eq. (1)'s C α'::

    F_f = Σ_{FL,FR} F(α'f; K_i, D_i),   F_r = Σ_{RL,RR} F(α'r; K_i, D_i)
    v̇y = (F_f + F_r)/m − vx r
    v̇x = 2/m [C_lf S_f + C_lr S_r] − (F_f δf,act + F_r δr,act)/m + vy r
    ṙ  = (a F_f − b F_r)/Iz + Mz/Iz

Each tyre sits at the quasi-static load F_z,i of the measured a_x, a_y
(``fourws_common.load_transfer``, held over the horizon) with its stiffness at that load,
K_i = C_c K_α(F_z,i)/K_α(F_z,static) (``axle_tyre.stiffness_at_load``): under lateral
transfer an axle is softer than at static load, 5.5 % at the front at 0.63 g and 0.6 of its
peak slip; with a_x = a_y = 0 the two tyres are the axle of static load (2 C_c, μ̂ m g b/L).
The peaks follow the estimated road and the friction ellipse. The yaw moment's longitudinal
forces, shared by load as the load-ratio allocation does (eq. 25-31), use the same fraction of
every wheel's grip on one side: η_R,L = (a_x ± 2 Mz/(B m))/(μ̂ g) with a_x the measured drive. So::

    D_i = μ̂ F_z,i ε(Mz),   ε = ½ [√(1 − η_L²) + √(1 − η_R²)]        (friction ellipse)

Linearised at (ζ0, u0) each step, the prediction sees the tyre's falling stiffness beyond its
peak and that a yaw moment costs lateral grip (successive linearisation, Falcone et al. 2007).
Jacobians are exact (tested against central finite differences of :func:`dynamics`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from fourws_common import load_transfer
from fourws_mpc.core import relaxation_model
from fourws_mpc.core.actuator_model import ActIdx
from fourws_mpc.core.axle_tyre import force, stiffness_at_load
from fourws_mpc.core.model import InputIdx, ModelParams, ModelTuple, StateIdx, as_vector, packed
from fourws_mpc.core.relaxation_model import RelaxIdx

N_STATE_FRICTION = relaxation_model.N_STATE_RELAX
#: |η| of one side is capped here: keeps √(1 − η²) and its slope finite
ETA_MAX = 0.99


@dataclass(frozen=True, slots=True)
class Grip:
    """The road the prediction assumes at one step: μ̂ and the measured a_x, a_y (m/s²; the
    controller keeps the a_y of the loads within μ_ceiling g)."""

    mu: float = 1.0
    ax_mps2: float = 0.0
    ay_mps2: float = 0.0


def axle_loads(p: ModelParams | ModelTuple) -> tuple[float, float]:
    """Static (F_z,f, F_z,r), N: the wheel loads at rest (``load_transfer``, their one owner)
    summed per axle."""
    fl, fr, rl, rr = load_transfer.loads(0.0, 0.0, p.mass_kg, p.a_m, p.b_m, p.cg_height_m,
                                         p.track_width_m, p.track_width_m,
                                         p.roll_stiffness_front_share, p.gravity_mps2)
    return fl + fr, rl + rr


_wheel_loads = njit(cache=True)(load_transfer.loads)


@njit(cache=True)
def _axle_loads(p: ModelTuple) -> tuple[float, float]:
    """:func:`axle_loads`, compiled."""
    fl, fr, rl, rr = _loads(p, 0.0, 0.0)
    return fl + fr, rl + rr


def ellipse(mz: float, p: ModelParams, g: Grip) -> tuple[float, float]:
    """(ε, ∂ε/∂Mz) of the module docstring."""
    return _ellipse(float(mz), packed(p), float(g.mu), float(g.ax_mps2))


@njit(cache=True)
def _ellipse(mz: float, p: ModelTuple, mu: float, ax: float) -> tuple[float, float]:
    cap = max(mu, 1e-3) * p.gravity_mps2
    k = 2.0 / (p.track_width_m * p.mass_kg * cap)
    eta_d = ax / cap
    eps, deps = 0.0, 0.0
    for sign in (1.0, -1.0):
        eta = eta_d + sign * k * mz
        if abs(eta) >= ETA_MAX:
            eta, slope = math.copysign(ETA_MAX, eta), 0.0
        else:
            slope = sign * k
        root = math.sqrt(1.0 - eta * eta)
        eps += 0.5 * root
        deps -= 0.5 * eta / root * slope
    return eps, deps


def axle_forces(zeta: np.ndarray, mz: float, p: ModelParams, g: Grip
                ) -> tuple[tuple[float, float, float], tuple[float, float, float], float]:
    """((F, ∂F/∂α', ∂F/∂Mz) front, the same rear, ε) at ζ_t."""
    return _axle_forces(as_vector(zeta), float(mz), packed(p), float(g.mu), float(g.ax_mps2),
                        float(g.ay_mps2))


@njit(cache=True)
def _axle_forces(zeta: np.ndarray, mz: float, p: ModelTuple, mu: float, ax: float, ay: float
                 ) -> tuple[tuple[float, float, float], tuple[float, float, float], float]:
    """:func:`axle_forces`, compiled."""
    eps, deps = _ellipse(mz, p, mu, ax)
    fz_f, fz_r = _axle_loads(p)
    fl, fr, rl, rr = _loads(p, ax, ay)
    front = _axle(zeta[RelaxIdx.ALPHA_F], p.c_cf, 0.5 * fz_f, fl, fr, mu, eps, deps, p)
    rear = _axle(zeta[RelaxIdx.ALPHA_R], p.c_cr, 0.5 * fz_r, rl, rr, mu, eps, deps, p)
    return front, rear, eps


@njit(cache=True)
def _loads(p: ModelTuple, ax: float, ay: float) -> tuple[float, float, float, float]:
    """The four wheels' quasi-static loads of a_x, a_y (N, FL FR RL RR)."""
    return _wheel_loads(ax, ay, p.mass_kg, p.a_m, p.b_m, p.cg_height_m, p.track_width_m,
                        p.track_width_m, p.roll_stiffness_front_share, p.gravity_mps2)


@njit(cache=True)
def tyre_sums(zeta: np.ndarray, p: ModelTuple, mu: float, eps: float, ax: float, ay: float
              ) -> tuple[float, float]:
    """(Σ_i F_i, Σ_i K_i α'_i) (N) of the four tyres at their loads of a_x, a_y on a road of
    μ with the ellipse share ε: the axles' force of the module docstring and its linear
    value (the μ estimate's evidence, ``grip``), compiled."""
    fz_f, fz_r = _axle_loads(p)
    fl, fr, rl, rr = _loads(p, ax, ay)
    a_f, a_r = zeta[RelaxIdx.ALPHA_F], zeta[RelaxIdx.ALPHA_R]
    k = p.tyre_stiffness_peak_load_n
    linear = (a_f * stiffness_at_load(p.c_cf, 0.5 * fz_f, fl, k)
              + a_f * stiffness_at_load(p.c_cf, 0.5 * fz_f, fr, k)
              + a_r * stiffness_at_load(p.c_cr, 0.5 * fz_r, rl, k)
              + a_r * stiffness_at_load(p.c_cr, 0.5 * fz_r, rr, k))
    force_sum = (_axle(a_f, p.c_cf, 0.5 * fz_f, fl, fr, mu, eps, 0.0, p)[0]
                 + _axle(a_r, p.c_cr, 0.5 * fz_r, rl, rr, mu, eps, 0.0, p)[0])
    return force_sum, linear


@njit(cache=True)
def _axle(alpha: float, c_static: float, fz_static: float, fz_left: float, fz_right: float,
          mu: float, eps: float, deps: float, p: ModelTuple) -> tuple[float, float, float]:
    """(F, ∂F/∂α', ∂F/∂Mz) of an axle's two tyres at their loads (module docstring)."""
    f, df_da, df_dmz = 0.0, 0.0, 0.0
    for fz in (fz_left, fz_right):
        if fz > 0.0:
            k = stiffness_at_load(c_static, fz_static, fz, p.tyre_stiffness_peak_load_n)
            peak = mu * fz
            fi, dfi_da, dfi_dd = force(alpha, k, peak * eps, p.tyre_shape_lateral,
                                       p.tyre_curvature_lateral)
            f, df_da, df_dmz = f + fi, df_da + dfi_da, df_dmz + dfi_dd * peak * deps
    return f, df_da, df_dmz


@njit(cache=True)
def _tyre_rows(out: np.ndarray, zeta: np.ndarray, u: np.ndarray, p: ModelTuple,
               ff: float, fr: float) -> np.ndarray:
    """The rows v̇y, v̇x, ṙ of the module docstring written into the relaxation model's
    f (``out``) with the axle forces ``ff``, ``fr``."""
    S = StateIdx
    vy, vx, r = zeta[S.VY], zeta[S.VX], zeta[S.R]
    m, iz = p.mass_kg, p.yaw_inertia_kg_m2
    out[S.VY] = (ff + fr) / m - vx * r
    out[S.VX] = (2.0 * (p.c_lf * p.slip_front + p.c_lr * p.slip_rear)
                 - ff * zeta[ActIdx.DF_ACT] - fr * zeta[ActIdx.DR_ACT]) / m + vy * r
    out[S.R] = (p.a_m * ff - p.b_m * fr + u[InputIdx.MZ]) / iz
    return out


def dynamics(zeta: np.ndarray, u: np.ndarray, p: ModelParams, g: Grip) -> np.ndarray:
    """f(ζ_t, u) of the module docstring. Shapes (10,), (3,) → (10,)."""
    relaxation_model.check(p)
    return _dynamics(as_vector(zeta), as_vector(u), packed(p), float(g.mu), float(g.ax_mps2),
                     float(g.ay_mps2))


def jacobians(zeta: np.ndarray, u: np.ndarray, p: ModelParams, g: Grip
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact ``(f, A_t (10, 10), B_t (10, 3))`` at (ζ_t, u): the relaxation model's rows of
    the positions, actuators and slips, and the tyre rows of the module docstring."""
    relaxation_model.check(p)
    return jacobians_compiled(as_vector(zeta), as_vector(u), packed(p), float(g.mu),
                              float(g.ax_mps2), float(g.ay_mps2))



@njit(cache=True)
def _dynamics(zeta: np.ndarray, u: np.ndarray, p: ModelTuple, mu: float, ax: float, ay: float
              ) -> np.ndarray:
    (ff, _, _), (fr, _, _), _ = _axle_forces(zeta, u[InputIdx.MZ], p, mu, ax, ay)
    return _tyre_rows(relaxation_model.dynamics_compiled(zeta, u, p), zeta, u, p, ff, fr)


@njit(cache=True)
def jacobians_compiled(zeta: np.ndarray, u: np.ndarray, p: ModelTuple, mu: float, ax: float,
                       ay: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`jacobians` on a :data:`~fourws_mpc.core.model.ModelTuple` and the road
    (μ̂, a_x, a_y), compiled."""
    S, A_, R_, I = StateIdx, ActIdx, RelaxIdx, InputIdx
    f, A, B = relaxation_model.jacobians_compiled(zeta, u, p)
    (ff, dff, mzf), (fr, dfr, mzr), _ = _axle_forces(zeta, u[I.MZ], p, mu, ax, ay)
    f = _tyre_rows(f, zeta, u, p, ff, fr)          # the forces computed once per step
    vy, vx, r = zeta[S.VY], zeta[S.VX], zeta[S.R]
    df, dr = zeta[A_.DF_ACT], zeta[A_.DR_ACT]
    m, iz, a, b = p.mass_kg, p.yaw_inertia_kg_m2, p.a_m, p.b_m
    for row in (S.VY, S.VX, S.R):
        A[row, :] = 0.0
        B[row, :] = 0.0
    A[S.VY, S.VX], A[S.VY, S.R] = -r, -vx
    A[S.VY, R_.ALPHA_F], A[S.VY, R_.ALPHA_R] = dff / m, dfr / m
    B[S.VY, I.MZ] = (mzf + mzr) / m
    A[S.VX, S.VY], A[S.VX, S.R] = r, vy
    A[S.VX, A_.DF_ACT], A[S.VX, A_.DR_ACT] = -ff / m, -fr / m
    A[S.VX, R_.ALPHA_F], A[S.VX, R_.ALPHA_R] = -dff * df / m, -dfr * dr / m
    B[S.VX, I.MZ] = -(mzf * df + mzr * dr) / m
    A[S.R, R_.ALPHA_F], A[S.R, R_.ALPHA_R] = a * dff / iz, -b * dfr / iz
    B[S.R, I.MZ] = (1.0 + a * mzf - b * mzr) / iz
    return f, A, B
