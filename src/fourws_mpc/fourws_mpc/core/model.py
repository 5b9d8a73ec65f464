"""Defines the 3-DOF single-track prediction model, eq. (1)-(4), with exact Jacobians.

The model of the 4WS vehicle (docs/mpc.md, "Model, eq. (1)-(4)"). State
ζ = [ẏ, ẋ, φ, φ̇, Y, X] = [vy, vx, φ, r, Y, X] (:class:`StateIdx`), input u = [δf, δr, Mz]
(:class:`InputIdx`), SI units (m/s, rad, rad/s, m, N·m).

Nonlinear model, eq. (1), with per-tyre cornering stiffnesses C_cf, C_cr (two tyres per axle,
hence the factor 2) and linear tyres::

    α_f = δf − (vy + a r)/vx,      α_r = δr − (vy − b r)/vx
    v̇x = 2/m [C_lf S_f + C_lr S_r − C_cf α_f δf − C_cr α_r δr] + vy r
    v̇y = 2/m [C_cf α_f + C_cr α_r] − vx r
    ṙ  = 2/Iz [a C_cf α_f − b C_cr α_r] + Mz/Iz
    φ̇  = r
    Ẏ  = vx sin φ + vy cos φ
    Ẋ  = vx cos φ − vy sin φ

Deviations from the printed paper (see ``docs/mpc.md``, "Deviations from the paper"):

* eq. (1) writes Mz inside ``2/Iz [...]``; the yaw moment enters as Mz/Iz (implemented).
* The printed B_t drops the factor 2 and the sign of the rear-steer yaw term, and the printed
  A_t has slips (a missing factor 2 in the ẍ row, the Y/X rows with swapped vy/vx columns);
  A_t and B_t here are the exact Jacobians of eq. (1): ∂v̇y/∂δf = 2C_cf/m, ∂v̇y/∂δr = 2C_cr/m,
  ∂ṙ/∂δf = 2aC_cf/Iz, ∂ṙ/∂δr = −2bC_cr/Iz, ∂ṙ/∂Mz = 1/Iz (tested against central finite
  differences of :func:`dynamics`).
* The longitudinal slip ratios S_f, S_r are parameters (default 0: the speed is held by the
  PID of eq. (24), which the lateral MPC does not model); vx is floored at ``min_speed_mps``
  inside the slip angles (assumption (5) of section 2).

Linearisation and discretisation, eq. (3)-(4), with an affine term so that the model is exact
at the operating point (ζ0, u0) (the paper's eq. (3)-(4) keep it implicitly as ζ̄(t))::

    ζ̇ ≈ f(ζ0, u0) + A_t (ζ − ζ0) + B_t (u − u0)
    ζ(k+1) = A_k ζ(k) + B_k u(k) + d_k,   A_k = I + T A_t,  B_k = T B_t,
    d_k = T [f(ζ0, u0) − A_t ζ0 − B_t u0]                                   # eq. (4)
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from enum import IntEnum
from functools import lru_cache
from typing import NamedTuple

import numpy as np
from numba import njit

from fourws_mpc.core.expm import expm, expm_compiled

N_STATE = 6
N_INPUT = 3


class StateIdx(IntEnum):
    """Indices of the prediction-model state ζ = [ẏ, ẋ, φ, φ̇, Y, X]."""

    VY = 0
    VX = 1
    PHI = 2
    R = 3
    Y = 4
    X = 5


class InputIdx(IntEnum):
    """Indices of the model input u = [δf, δr, Mz]."""

    DF = 0
    DR = 1
    MZ = 2


@dataclass(frozen=True, slots=True)
class ModelParams:
    """Parameters of eq. (1) in SI units; C_cf, C_cr, C_lf, C_lr are per tyre; the steering
    time constants belong to the actuator-aware model (``actuator_model``), the relaxation
    lengths to the relaxation-aware one (``relaxation_model``)."""

    mass_kg: float = 750.0
    yaw_inertia_kg_m2: float = 750.0
    a_m: float = 1.10
    b_m: float = 1.25
    c_cf: float = 28000.0
    c_cr: float = 30000.0
    c_lf: float = 50000.0
    c_lr: float = 50000.0
    slip_front: float = 0.0
    slip_rear: float = 0.0
    min_speed_mps: float = 1.0
    #: first-order steering lags τ_f, τ_r (s), used by the actuator-aware prediction model
    #: only (``actuator_model``); eq. (1) takes the commanded angles
    steer_front_time_constant_s: float = 0.02
    steer_rear_time_constant_s: float = 0.02
    #: lateral relaxation lengths σ_f, σ_r (m) at static load, used by the relaxation-aware
    #: model only (``relaxation_model``); eq. (1)'s tyre forces act at once
    relaxation_length_front_m: float = 0.2199
    relaxation_length_rear_m: float = 0.1995
    #: the friction-aware model's (``friction_model``): g, track B, axle tyre's MF C and E
    gravity_mps2: float = 9.81
    track_width_m: float = 1.30
    tyre_shape_lateral: float = 1.3
    tyre_curvature_lateral: float = -1.0
    #: the tyres' loads (``friction_model``, ``grip``): CG height h, front roll-stiffness
    #: share χ_f (the quasi-static load transfer) and the load where a tyre's K_α peaks,
    #: p_Ky2 F_z0
    cg_height_m: float = 0.54
    roll_stiffness_front_share: float = 0.55
    tyre_stiffness_peak_load_n: float = 4000.0


#: :class:`ModelParams` as the NamedTuple of floats the compiled kernels take, field for field
ModelTuple = NamedTuple("ModelTuple", [(f.name, float) for f in dataclasses.fields(ModelParams)])


def as_vector(x: np.ndarray) -> np.ndarray:
    """``x`` as a contiguous float array (what the compiled kernels take)."""
    return np.ascontiguousarray(x, dtype=float)


@lru_cache(maxsize=64)
def packed(p: ModelParams) -> ModelTuple:
    """``p`` as a :data:`ModelTuple` (built once per parameter set)."""
    return ModelTuple(*(float(getattr(p, name)) for name in ModelTuple._fields))


def axle_directions(vy: float, r: float, vxs: float, p: ModelParams) -> tuple[float, float]:
    """((v_y + a r)/v_x, (v_y − b r)/v_x): the direction of each axle's velocity (rad, small
    angles), the part of eq. (1)'s slip angles α = δ − (·) the wheels do not set; ``vxs`` the
    speed already floored at ``min_speed_mps`` by the caller."""
    return (vy + p.a_m * r) / vxs, (vy - p.b_m * r) / vxs


def dynamics(zeta: np.ndarray, u: np.ndarray, p: ModelParams) -> np.ndarray:
    """Nonlinear right-hand side f(ζ, u) of eq. (1) (with Mz/Iz). Shapes (6,), (3,) → (6,)."""
    vy, vx, phi, r = zeta[StateIdx.VY], zeta[StateIdx.VX], zeta[StateIdx.PHI], zeta[StateIdx.R]
    df, dr, mz = u[InputIdx.DF], u[InputIdx.DR], u[InputIdx.MZ]
    vxs = max(vx, p.min_speed_mps)
    wf, wr = axle_directions(vy, r, vxs, p)
    af = df - wf
    ar = dr - wr
    out = np.empty(N_STATE)
    out[StateIdx.VY] = 2.0 / p.mass_kg * (p.c_cf * af + p.c_cr * ar) - vx * r
    out[StateIdx.VX] = 2.0 / p.mass_kg * (
        p.c_lf * p.slip_front + p.c_lr * p.slip_rear - p.c_cf * af * df - p.c_cr * ar * dr
    ) + vy * r
    out[StateIdx.PHI] = r
    out[StateIdx.R] = 2.0 / p.yaw_inertia_kg_m2 * (p.a_m * p.c_cf * af - p.b_m * p.c_cr * ar) + (
        mz / p.yaw_inertia_kg_m2
    )
    s, c = np.sin(phi), np.cos(phi)
    out[StateIdx.Y] = vx * s + vy * c
    out[StateIdx.X] = vx * c - vy * s
    return out


def jacobians(
    zeta: np.ndarray, u: np.ndarray, p: ModelParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact continuous-time Jacobians of eq. (1) at (ζ, u).

    Returns ``(f0, A_t, B_t)``: f(ζ, u) (6,), ∂f/∂ζ (6, 6), ∂f/∂u (6, 3). When vx is below
    ``min_speed_mps`` the slip angles use the floored speed and their vx-derivatives vanish.
    """
    S, I = StateIdx, InputIdx
    vy, vx, phi, r = zeta[S.VY], zeta[S.VX], zeta[S.PHI], zeta[S.R]
    df, dr = u[I.DF], u[I.DR]
    m, iz, a, b = p.mass_kg, p.yaw_inertia_kg_m2, p.a_m, p.b_m
    cf, cr = p.c_cf, p.c_cr
    floored = vx < p.min_speed_mps
    vxs = p.min_speed_mps if floored else vx
    wf, wr = axle_directions(vy, r, vxs, p)
    af = df - wf
    ar = dr - wr
    # partial derivatives of the slip angles
    daf_dvy, dar_dvy = -1.0 / vxs, -1.0 / vxs
    daf_dr, dar_dr = -a / vxs, b / vxs
    daf_dvx, dar_dvx = (0.0, 0.0) if floored else (wf / vxs, wr / vxs)

    f0 = dynamics(zeta, u, p)
    A = np.zeros((N_STATE, N_STATE))
    B = np.zeros((N_STATE, N_INPUT))
    k = 2.0 / m
    A[S.VY, S.VY] = k * (cf * daf_dvy + cr * dar_dvy)
    A[S.VY, S.VX] = k * (cf * daf_dvx + cr * dar_dvx) - r
    A[S.VY, S.R] = k * (cf * daf_dr + cr * dar_dr) - vx
    B[S.VY, I.DF] = k * cf
    B[S.VY, I.DR] = k * cr

    A[S.VX, S.VY] = -k * (cf * df * daf_dvy + cr * dr * dar_dvy) + r
    A[S.VX, S.VX] = -k * (cf * df * daf_dvx + cr * dr * dar_dvx)
    A[S.VX, S.R] = -k * (cf * df * daf_dr + cr * dr * dar_dr) + vy
    B[S.VX, I.DF] = -k * cf * (af + df)
    B[S.VX, I.DR] = -k * cr * (ar + dr)

    A[S.PHI, S.R] = 1.0

    kz = 2.0 / iz
    A[S.R, S.VY] = kz * (a * cf * daf_dvy - b * cr * dar_dvy)
    A[S.R, S.VX] = kz * (a * cf * daf_dvx - b * cr * dar_dvx)
    A[S.R, S.R] = kz * (a * cf * daf_dr - b * cr * dar_dr)
    B[S.R, I.DF] = kz * a * cf
    B[S.R, I.DR] = -kz * b * cr
    B[S.R, I.MZ] = 1.0 / iz

    s, c = np.sin(phi), np.cos(phi)
    A[S.Y, S.VY] = c
    A[S.Y, S.VX] = s
    A[S.Y, S.PHI] = vx * c - vy * s
    A[S.X, S.VY] = -s
    A[S.X, S.VX] = c
    A[S.X, S.PHI] = -vx * s - vy * c
    return f0, A, B


def zoh(A: np.ndarray, B: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretisation (A_d, B_d) of ẋ = A x + B u by the matrix exponential
    expm(T [[A, B], [0, 0]]) = [[A_d, B_d], [0, I]] (the one copy: MPC, LQR, margins; the
    exponential is the compiled ``expm``)."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A, B
    E = expm(M * dt_s)
    return E[:n, :n], E[:n, n:]


@njit(cache=True)
def affine_euler(f0: np.ndarray, At: np.ndarray, Bt: np.ndarray, zeta0: np.ndarray,
                 u0: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Forward Euler of the linearisation at (ζ0, u0), eq. (4): A_k = I + T A_t,
    B_k = T B_t, d_k = T (f0 − A_t ζ0 − B_t u0), exact at the operating point (compiled)."""
    Ak = dt_s * At
    for i in range(Ak.shape[0]):
        Ak[i, i] += 1.0
    return Ak, dt_s * Bt, dt_s * (f0 - At @ zeta0 - Bt @ u0)


@njit(cache=True)
def affine_zoh(f0: np.ndarray, At: np.ndarray, Bt: np.ndarray, zeta0: np.ndarray,
               u0: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact zero-order hold of the same linearisation: the constant term
    c = f0 − A_t ζ0 − B_t u0 is a held input, so d_k is its column of :func:`zoh`
    (compiled: expm(T [[A_t, B_t, c], [0, 0, 0]]) in one kernel)."""
    n, m = Bt.shape
    M = np.zeros((n + m + 1, n + m + 1))
    M[:n, :n] = dt_s * At
    M[:n, n:n + m] = dt_s * Bt
    M[:n, n + m] = dt_s * (f0 - At @ zeta0 - Bt @ u0)
    E = expm_compiled(M)
    return (np.ascontiguousarray(E[:n, :n]), np.ascontiguousarray(E[:n, n:n + m]),
            np.ascontiguousarray(E[:n, n + m]))


def discretise(
    zeta0: np.ndarray, u0: np.ndarray, p: ModelParams, dt_s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Forward-Euler LTV model of eq. (4) linearised at (ζ0, u0) (:func:`affine_euler`).

    Returns ``(A_k, B_k, d_k)`` with ζ(k+1) = A_k ζ + B_k u + d_k, exact at (ζ0, u0):
    A_k = I + T A_t (6, 6), B_k = T B_t (6, 3), d_k = T (f0 − A_t ζ0 − B_t u0) (6,).
    """
    return affine_euler(*jacobians(zeta0, u0, p), zeta0, u0, dt_s)


def euler_step(zeta: np.ndarray, u: np.ndarray, p: ModelParams, dt_s: float) -> np.ndarray:
    """One forward-Euler step of the nonlinear model: ζ + T f(ζ, u). Shape (6,)."""
    return zeta + dt_s * dynamics(zeta, u, p)
