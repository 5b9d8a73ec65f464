"""Extends the single-track model of eq. (1) by the steering actuators' first-order lag.

A documented deviation from the paper's assumption (6) that the commanded road-wheel angles act
at once (``docs/mpc.md``, "Actuator-aware prediction"). The state is ζ of eq. (1) with the
actual road-wheel angles appended after :attr:`~fourws_mpc.core.model.StateIdx.X` (so every
index of ζ keeps its meaning)::

    ζ_a = [vy, vx, φ, r, Y, X, δf,act, δr,act]        (:class:`ActIdx`)
    u   = [δf,cmd, δr,cmd, Mz]                          (:class:`~fourws_mpc.core.model.InputIdx`)

and the dynamics are eq. (1) with the actual angles in the slip angles, plus the plant's
actuator law (``fourws_sim.core.actuators.steer_derivative`` without its rate limit)::

    f_a(ζ_a, u) = [ f(ζ, [δf,act, δr,act, Mz]) ;
                    (δf,cmd − δf,act)/τ_f ;
                    (δr,cmd − δr,act)/τ_r ]                                   (eq. 1 + lag)

τ_f, τ_r are ``steer_front_time_constant_s``, ``steer_rear_time_constant_s`` (the plant's names
and values in the car file). The yaw moment still acts at once (the motors' eq. (32) is not
modelled). Jacobians are exact, by the chain rule through ``model.jacobians``, with (A_t, B_t)
of eq. (1) at the actual angles (tested against central finite differences of :func:`dynamics`)::

    A_a = [[A_t, B_t[:, δf], B_t[:, δr]], [0, −1/τ_f, 0], [0, 0, −1/τ_r]]
    B_a = [[0, 0, B_t[:, Mz]], [1/τ_f, 0, 0], [0, 1/τ_r, 0]]
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np

from fourws_mpc.core.model import N_INPUT, N_STATE, InputIdx, ModelParams
from fourws_mpc.core.model import dynamics as _base_dynamics
from fourws_mpc.core.model import jacobians as _base_jacobians

N_STATE_ACT = N_STATE + 2


class ActIdx(IntEnum):
    """Indices of the appended actuator states (after ``StateIdx.X``)."""

    DF_ACT = N_STATE
    DR_ACT = N_STATE + 1


def _actual_input(zeta: np.ndarray, u: np.ndarray) -> np.ndarray:
    """[δf,act, δr,act, Mz]: what the tyres and the body feel."""
    ua = np.empty(N_INPUT)
    ua[InputIdx.DF] = zeta[ActIdx.DF_ACT]
    ua[InputIdx.DR] = zeta[ActIdx.DR_ACT]
    ua[InputIdx.MZ] = u[InputIdx.MZ]
    return ua


def dynamics(zeta: np.ndarray, u: np.ndarray, p: ModelParams) -> np.ndarray:
    """f_a(ζ_a, u) of the module docstring. Shapes (8,), (3,) → (8,)."""
    out = np.empty(N_STATE_ACT)
    out[:N_STATE] = _base_dynamics(zeta[:N_STATE], _actual_input(zeta, u), p)
    out[ActIdx.DF_ACT] = (u[InputIdx.DF] - zeta[ActIdx.DF_ACT]) / p.steer_front_time_constant_s
    out[ActIdx.DR_ACT] = (u[InputIdx.DR] - zeta[ActIdx.DR_ACT]) / p.steer_rear_time_constant_s
    return out


def jacobians(zeta: np.ndarray, u: np.ndarray, p: ModelParams
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact ``(f_a, A_a (8, 8), B_a (8, 3))`` at (ζ_a, u), module docstring."""
    f0, At, Bt = _base_jacobians(zeta[:N_STATE], _actual_input(zeta, u), p)
    tf, tr = p.steer_front_time_constant_s, p.steer_rear_time_constant_s
    f = np.empty(N_STATE_ACT)
    f[:N_STATE] = f0
    f[ActIdx.DF_ACT] = (u[InputIdx.DF] - zeta[ActIdx.DF_ACT]) / tf
    f[ActIdx.DR_ACT] = (u[InputIdx.DR] - zeta[ActIdx.DR_ACT]) / tr
    A = np.zeros((N_STATE_ACT, N_STATE_ACT))
    B = np.zeros((N_STATE_ACT, N_INPUT))
    A[:N_STATE, :N_STATE] = At
    A[:N_STATE, ActIdx.DF_ACT] = Bt[:, InputIdx.DF]
    A[:N_STATE, ActIdx.DR_ACT] = Bt[:, InputIdx.DR]
    B[:N_STATE, InputIdx.MZ] = Bt[:, InputIdx.MZ]
    A[ActIdx.DF_ACT, ActIdx.DF_ACT] = -1.0 / tf
    A[ActIdx.DR_ACT, ActIdx.DR_ACT] = -1.0 / tr
    B[ActIdx.DF_ACT, InputIdx.DF] = 1.0 / tf
    B[ActIdx.DR_ACT, InputIdx.DR] = 1.0 / tr
    return f, A, B
