"""Computes a textbook front-steer law: discrete LQR plus steady-state curvature feed-forward.

The reference beside the MPC (docs/mpc.md, "The textbook reference `lqr_ff`"). Error model
(Rajamani, *Vehicle Dynamics and Control*, 2nd ed., 2012, sec. 2.5 and 3.2), per-tyre
cornering stiffnesses C_f, C_r (two tyres per axle), speed V_x, states x = [e1, ė1, e2, ė2]
(lateral offset of the CG from the path, m, left +; its rate; heading error ψ − ψ_ref, rad;
its rate), input the front road-wheel angle δ::

    ẋ = A x + B δ + B_κ ψ̇_des,     ψ̇_des = V_x κ

    A = [[0, 1, 0, 0],
         [0, −2(C_f+C_r)/(m V_x), 2(C_f+C_r)/m, 2(−C_f a + C_r b)/(m V_x)],
         [0, 0, 0, 1],
         [0, −2(C_f a − C_r b)/(I_z V_x), 2(C_f a − C_r b)/I_z, −2(C_f a² + C_r b²)/(I_z V_x)]]
    B = [0, 2 C_f/m, 0, 2 C_f a/I_z]ᵀ

Feedback δ_fb = −K x, K the discrete LQR gain of (A, B) sampled with a zero-order hold at the
control period T (``scipy.linalg.solve_discrete_are``); Bryson's-rule weights (Bryson & Ho,
*Applied Optimal Control*, 1975) Q = diag(1/x_i,max²), R = 1/δ_max², with the largest
acceptable value of each state and of the input (:class:`LqrWeights`). The feed-forward for a
constant curvature κ (Rajamani eq. 3.12), with L = a + b, K_V = (b m)/(2 C_f L) − (a m)/(2 C_r L)
the understeer gradient and a_y = V_x² κ::

    δ_ff = L κ + K_V a_y − k₃ (b κ − a m V_x² κ / (2 C_r L))

makes the steady-state lateral offset zero (the heading error stays at its kinematic value).
The gain is scheduled on V_x (recomputed when the speed has moved by more than
``speed_step_mps``) and the controller reads no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fourws_mpc.core.model import ModelParams, zoh


class ErrIdx:
    """Indices of the error state."""

    E1 = 0      # lateral offset, m
    E1_DOT = 1  # m/s
    E2 = 2      # heading error, rad
    E2_DOT = 3  # rad/s


@dataclass(frozen=True)
class LqrWeights:
    """Bryson's rule: the largest acceptable value of each state and of the steer angle."""

    e1_max_m: float = 0.05
    e1_dot_max_mps: float = 0.5
    e2_max_rad: float = math.radians(1.0)
    e2_dot_max_rad_s: float = math.radians(10.0)
    steer_max_rad: float = math.radians(5.0)

    def q(self) -> np.ndarray:
        """Q = diag(1/x_max²)."""
        return np.diag([1.0 / self.e1_max_m**2, 1.0 / self.e1_dot_max_mps**2,
                        1.0 / self.e2_max_rad**2, 1.0 / self.e2_dot_max_rad_s**2])

    def r(self) -> np.ndarray:
        """R = 1/δ_max²."""
        return np.array([[1.0 / self.steer_max_rad**2]])


def error_model(p: ModelParams, vx: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A (4,4), B (4,1), B_κ (4,1)) of the lateral-error model at speed ``vx`` (m/s)."""
    vx = max(vx, p.min_speed_mps)
    m, iz, a, b = p.mass_kg, p.yaw_inertia_kg_m2, p.a_m, p.b_m
    cf, cr = 2.0 * p.c_cf, 2.0 * p.c_cr          # per axle
    A = np.array([
        [0.0, 1.0, 0.0, 0.0],
        [0.0, -(cf + cr) / (m * vx), (cf + cr) / m, (-cf * a + cr * b) / (m * vx)],
        [0.0, 0.0, 0.0, 1.0],
        [0.0, -(cf * a - cr * b) / (iz * vx), (cf * a - cr * b) / iz,
         -(cf * a * a + cr * b * b) / (iz * vx)],
    ])
    B = np.array([[0.0], [cf / m], [0.0], [cf * a / iz]])
    Bk = np.array([[0.0], [(-cf * a + cr * b) / (m * vx) - vx], [0.0],
                   [-(cf * a * a + cr * b * b) / (iz * vx)]])
    return A, B, Bk


def dlqr_gain(Ad: np.ndarray, Bd: np.ndarray, Q: np.ndarray, R: np.ndarray) -> np.ndarray:
    """K (1, 4) of u = −K x minimising Σ xᵀQx + uᵀRu (discrete Riccati equation)."""
    import scipy.linalg  # here: only lqr_ff solves it, and the MPC's process starts without it

    P = scipy.linalg.solve_discrete_are(Ad, Bd, Q, R)
    return np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)


def feedforward(p: ModelParams, vx: float, curvature: float, k3: float) -> float:
    """δ_ff (rad) for curvature ``curvature`` (1/m, left +) at ``vx`` with heading gain k₃."""
    m, a, b = p.mass_kg, p.a_m, p.b_m
    cf, cr = 2.0 * p.c_cf, 2.0 * p.c_cr
    L = a + b
    k_v = b * m / (cf * L) - a * m / (cr * L)
    ay = vx * vx * curvature
    return L * curvature + k_v * ay - k3 * (b * curvature - a * m * vx * vx * curvature
                                            / (cr * L))


class LqrLateral:
    """δ = −K x + δ_ff, K scheduled on V_x; stateless between steps but for the gain cache."""

    def __init__(self, params: ModelParams, dt_s: float, weights: LqrWeights | None = None,
                 speed_step_mps: float = 0.5) -> None:
        self.params, self.dt_s = params, dt_s
        self.weights = weights if weights is not None else LqrWeights()
        self.speed_step_mps = speed_step_mps
        self._vx: float | None = None
        self.K = np.zeros((1, 4))

    def gain(self, vx: float) -> np.ndarray:
        """K (1, 4) at ``vx``, recomputed when the speed moved by more than the step."""
        if self._vx is None or abs(vx - self._vx) > self.speed_step_mps:
            A, B, _ = error_model(self.params, vx)
            Ad, Bd = zoh(A, B, self.dt_s)
            self.K = dlqr_gain(Ad, Bd, self.weights.q(), self.weights.r())
            self._vx = vx
        return self.K

    def steer(self, x: np.ndarray, vx: float, curvature: float) -> float:
        """Front road-wheel angle (rad) for the error state ``x`` (4,)."""
        K = self.gain(vx)
        return float(-(K @ x)[0] + feedforward(self.params, vx, curvature, float(K[0, 2])))
