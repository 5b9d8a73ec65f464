"""Extends the single-track model by the steering lags and the tyres' lateral relaxation.

A documented deviation from the paper's assumption (6) and from eq. (1)'s instantaneous tyre
force (``docs/mpc.md``, "Relaxation-aware prediction"): the plant's tyres build their lateral
force over a rolling distance σ (Pacejka 2012, §7.2; ``fourws_sim.core.vehicle``), a lag of
σ/v_x. Here the axle's transient slip angle α' is a state, appended after the actuator states
of ``actuator_model``::

    ζ_t = [vy, vx, φ, r, Y, X, δf,act, δr,act, α'f, α'r]      (:class:`RelaxIdx`)
    u   = [δf,cmd, δr,cmd, Mz]

and the forces of eq. (1) act on α' instead of the kinematic slip angles::

    v̇y = 2/m [C_cf α'f + C_cr α'r] − vx r
    v̇x = 2/m [C_lf S_f + C_lr S_r − C_cf α'f δf,act − C_cr α'r δr,act] + vy r
    ṙ  = 2/Iz [a C_cf α'f − b C_cr α'r] + Mz/Iz
    φ̇, Ẏ, Ẋ as eq. (1);  δ̇_act = (δ_cmd − δ_act)/τ   (actuator_model)
    α̇'f = (α_f − α'f) vx/σ_f = [vx (δf,act − α'f) − vy − a r]/σ_f
    α̇'r = (α_r − α'r) vx/σ_r = [vx (δr,act − α'r) − vy + b r]/σ_r        (relaxation)

with α_f = δf,act − (vy + a r)/vx the kinematic slip angle of eq. (1), vx floored at
``min_speed_mps`` (whose vx-derivative then vanishes), σ_f, σ_r the relaxation lengths at
static load (``relaxation_length_front_m``, ``relaxation_length_rear_m``; the plant's MF 5.2
σ_α0 of the car file). With α' = α (σ → 0) this is ``actuator_model``.

α' is not measured: :class:`SlipObserver` estimates it by running the same lag on the measured
kinematic slip (from vy, r, vx and the road-wheel angles); F_y = 2 C α' per axle is the
"estimated F_y" a car without force sensors has. Jacobians are exact (tested against central
finite differences of :func:`dynamics`); the rows of the actuator and position states are
those of ``actuator_model`` and ``model``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numba import njit

from fourws_mpc.core.actuator_model import N_STATE_ACT, ActIdx
from fourws_mpc.core.model import (
    InputIdx,
    ModelParams,
    ModelTuple,
    StateIdx,
    as_vector,
    axle_directions,
    packed,
)

N_STATE_RELAX = N_STATE_ACT + 2
N_INPUT = 3


class RelaxIdx(IntEnum):
    """Indices of the appended transient slip angles (after ``ActIdx.DR_ACT``)."""

    ALPHA_F = N_STATE_ACT
    ALPHA_R = N_STATE_ACT + 1


def check(p: ModelParams) -> tuple[float, float]:
    sf, sr = p.relaxation_length_front_m, p.relaxation_length_rear_m
    if not (sf > 0.0 and sr > 0.0):
        raise ValueError("relaxation_length_front_m, relaxation_length_rear_m: must be > 0 "
                         f"for the relaxation model, got {sf}, {sr}")
    return sf, sr


def kinematic_slip(zeta: np.ndarray, p: ModelParams) -> tuple[float, float]:
    """(α_f, α_r) of eq. (1) at the actual road-wheel angles of ζ_t (or of the actuator
    model's ζ_a: the first eight states)."""
    vxs = max(zeta[StateIdx.VX], p.min_speed_mps)
    wf, wr = axle_directions(zeta[StateIdx.VY], zeta[StateIdx.R], vxs, p)
    return float(zeta[ActIdx.DF_ACT] - wf), float(zeta[ActIdx.DR_ACT] - wr)


def dynamics(zeta: np.ndarray, u: np.ndarray, p: ModelParams) -> np.ndarray:
    """f_t(ζ_t, u) of the module docstring. Shapes (10,), (3,) → (10,)."""
    check(p)
    return dynamics_compiled(as_vector(zeta), as_vector(u), packed(p))


def jacobians(zeta: np.ndarray, u: np.ndarray, p: ModelParams
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact ``(f_t, A_t (10, 10), B_t (10, 3))`` at (ζ_t, u), module docstring."""
    check(p)
    return jacobians_compiled(as_vector(zeta), as_vector(u), packed(p))



@njit(cache=True)
def dynamics_compiled(zeta: np.ndarray, u: np.ndarray, p: ModelTuple) -> np.ndarray:
    """:func:`dynamics` on a :data:`~fourws_mpc.core.model.ModelTuple` (σ > 0 checked by
    the caller), compiled."""
    S, A_, R_ = StateIdx, ActIdx, RelaxIdx
    sf, sr = p.relaxation_length_front_m, p.relaxation_length_rear_m
    vy, vx, phi, r = zeta[S.VY], zeta[S.VX], zeta[S.PHI], zeta[S.R]
    df, dr = zeta[A_.DF_ACT], zeta[A_.DR_ACT]
    af, ar = zeta[R_.ALPHA_F], zeta[R_.ALPHA_R]
    vxs = max(vx, p.min_speed_mps)
    m, iz, a, b = p.mass_kg, p.yaw_inertia_kg_m2, p.a_m, p.b_m
    out = np.empty(N_STATE_RELAX)
    out[S.VY] = 2.0 / m * (p.c_cf * af + p.c_cr * ar) - vx * r
    out[S.VX] = 2.0 / m * (p.c_lf * p.slip_front + p.c_lr * p.slip_rear
                           - p.c_cf * af * df - p.c_cr * ar * dr) + vy * r
    out[S.PHI] = r
    out[S.R] = 2.0 / iz * (a * p.c_cf * af - b * p.c_cr * ar) + u[InputIdx.MZ] / iz
    s, c = math.sin(phi), math.cos(phi)
    out[S.Y] = vx * s + vy * c
    out[S.X] = vx * c - vy * s
    out[A_.DF_ACT] = (u[InputIdx.DF] - df) / p.steer_front_time_constant_s
    out[A_.DR_ACT] = (u[InputIdx.DR] - dr) / p.steer_rear_time_constant_s
    out[R_.ALPHA_F] = (vxs * (df - af) - vy - a * r) / sf
    out[R_.ALPHA_R] = (vxs * (dr - ar) - vy + b * r) / sr
    return out


@njit(cache=True)
def jacobians_compiled(zeta: np.ndarray, u: np.ndarray, p: ModelTuple
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`jacobians` on a :data:`~fourws_mpc.core.model.ModelTuple`, compiled."""
    S, A_, R_, I = StateIdx, ActIdx, RelaxIdx, InputIdx
    sf, sr = p.relaxation_length_front_m, p.relaxation_length_rear_m
    vy, vx, phi, r = zeta[S.VY], zeta[S.VX], zeta[S.PHI], zeta[S.R]
    df, dr = zeta[A_.DF_ACT], zeta[A_.DR_ACT]
    af, ar = zeta[R_.ALPHA_F], zeta[R_.ALPHA_R]
    floored = vx < p.min_speed_mps
    vxs = p.min_speed_mps if floored else vx
    m, iz, a, b = p.mass_kg, p.yaw_inertia_kg_m2, p.a_m, p.b_m
    cf, cr = p.c_cf, p.c_cr
    tf, tr = p.steer_front_time_constant_s, p.steer_rear_time_constant_s
    f = dynamics_compiled(zeta, u, p)
    A = np.zeros((N_STATE_RELAX, N_STATE_RELAX))
    B = np.zeros((N_STATE_RELAX, N_INPUT))
    k, kz = 2.0 / m, 2.0 / iz
    A[S.VY, S.VX] = -r
    A[S.VY, S.R] = -vx
    A[S.VY, R_.ALPHA_F], A[S.VY, R_.ALPHA_R] = k * cf, k * cr

    A[S.VX, S.VY] = r
    A[S.VX, S.R] = vy
    A[S.VX, A_.DF_ACT], A[S.VX, A_.DR_ACT] = -k * cf * af, -k * cr * ar
    A[S.VX, R_.ALPHA_F], A[S.VX, R_.ALPHA_R] = -k * cf * df, -k * cr * dr

    A[S.PHI, S.R] = 1.0
    A[S.R, R_.ALPHA_F], A[S.R, R_.ALPHA_R] = kz * a * cf, -kz * b * cr
    B[S.R, I.MZ] = 1.0 / iz

    s, c = math.sin(phi), math.cos(phi)
    A[S.Y, S.VY], A[S.Y, S.VX], A[S.Y, S.PHI] = c, s, vx * c - vy * s
    A[S.X, S.VY], A[S.X, S.VX], A[S.X, S.PHI] = -s, c, -vx * s - vy * c

    A[A_.DF_ACT, A_.DF_ACT], B[A_.DF_ACT, I.DF] = -1.0 / tf, 1.0 / tf
    A[A_.DR_ACT, A_.DR_ACT], B[A_.DR_ACT, I.DR] = -1.0 / tr, 1.0 / tr

    _slip_row(A, R_.ALPHA_F, A_.DF_ACT, sf, df, af, a, vxs, floored)
    _slip_row(A, R_.ALPHA_R, A_.DR_ACT, sr, dr, ar, -b, vxs, floored)
    return f, A, B


@njit(cache=True)
def _slip_row(A: np.ndarray, row: int, act: int, sig: float, d: float, al: float,
              arm: float, vxs: float, floored: bool) -> None:
    """The row of α̇' of one axle (steering state ``act``, lever ``arm``: a, or −b)."""
    A[row, StateIdx.VY] = -1.0 / sig
    A[row, StateIdx.R] = -arm / sig
    A[row, StateIdx.VX] = 0.0 if floored else (d - al) / sig
    A[row, act] = vxs / sig
    A[row, row] = -vxs / sig


def hold_coefficients(dt_s: float, vx: float, sigma_m: float) -> tuple[float, float]:
    """(e, g) of :class:`SlipObserver`'s first-order hold: x = T vx/σ, e = exp(−x),
    g = (1 − e)/x (accurate for small x), so α̂'(k) = e α̂'(k−1) + (1 − g) α(k) + (g − e) α(k−1)
    (the one statement; :func:`observer_state_space` is its linear form)."""
    x = dt_s * vx / sigma_m
    return math.exp(-x), (-math.expm1(-x) / x if x != 0.0 else 1.0)   # g → 1 as x → 0


def observer_state_space(dt_s: float, vx: float, sigma_m: float
                         ) -> tuple[float, float, float, float]:
    """(a, b, c, d) of :class:`SlipObserver` as a linear system in its memory
    m(k) = e α̂'(k−1) + (g − e) α(k−1): m(k+1) = a m(k) + b α(k), α̂'(k) = c m(k) + d α(k),
    with a = e, b = g (1 − e), c = 1, d = 1 − g (:func:`hold_coefficients`); what the
    stability margins close the loop with (``fourws_bringup.core.margins``)."""
    e, g = hold_coefficients(dt_s, vx, sigma_m)
    return e, g * (1.0 - e), 1.0, 1.0 - g


@dataclass(frozen=True, slots=True)
class ObserverMemory:
    """What :class:`SlipObserver` carries from one step to the next: the estimate α̂' and
    the kinematic slip it was last driven by (rad)."""

    alpha_hat: tuple[float, float]
    alpha_kin: tuple[float, float]


class SlipObserver:
    """Estimate of the transient slip α' from the measured kinematic slip α (rad).

    The relaxation lag τ = σ/vx of the module docstring run on the measured α, which is
    taken to vary linearly between two samples (first-order hold; exact for that input)::

        α̂'(k) = e α̂'(k−1) + (1 − (1 − e)/x) α(k) + ((1 − e)/x − e) α(k−1),
        x = T vx/σ,  e = exp(−x)

    With no memory (the first step, after a reset) it starts at α̂' = α: the steady state.
    Pure: :meth:`estimate` returns the next memory, which the caller commits.
    """

    def __init__(self, params: ModelParams) -> None:
        self.params = params
        check(params)

    def estimate(self, zeta: np.ndarray, memory: ObserverMemory | None, dt_s: float
                 ) -> tuple[tuple[float, float], ObserverMemory]:
        """(α̂'f, α̂'r) at the measured ζ_a (the first eight states of ζ_t) and the memory
        for the next step."""
        p = self.params
        alpha = kinematic_slip(zeta, p)
        if memory is None:
            return alpha, ObserverMemory(alpha, alpha)
        vxs = max(float(zeta[StateIdx.VX]), p.min_speed_mps)
        out = []
        for hat, prev, now, sig in zip(memory.alpha_hat, memory.alpha_kin, alpha,
                                       (p.relaxation_length_front_m,
                                        p.relaxation_length_rear_m), strict=True):
            e, g = hold_coefficients(dt_s, vxs, sig)
            out.append(e * hat + (1.0 - g) * now + (g - e) * prev)
        est = (out[0], out[1])
        return est, ObserverMemory(est, alpha)
