"""Models the four in-wheel motors, eq. (32), and the front and rear steering actuators.

In-wheel motor, eq. (32) (docs/plant.md, "Vehicle"): actual torque T_m follows the command T_md
through

    G(s) = T_m / T_md = 1 / (2τ² s² + 2τ s + 1),      τ = 0.02 s (Table 5)

i.e. a second-order lag with ω_n = 1/(√2 τ) ≈ 35.4 rad/s and damping ζ = 1/√2 (step
overshoot e^(−π) ≈ 4.32 %). State space, two states per motor (torque and its rate)::

    d/dt [T, Ṫ] = [Ṫ, (T_md − T − 2τ Ṫ) / (2τ²)]

The command is clipped to ±``motor_torque_max_nm`` before it enters the lag, so the actual
torque can overshoot the limit by the 4.3 % of the lag itself, as an inner current loop
with a saturated reference would.

Steering actuators (parallel steer: both front wheels at δ_f, both rear wheels at δ_r):
a first-order position lag with a rate limit, the command clipped to the angle limits::

    δ̇ = sat((sat(δ_cmd, ±δ_max) − δ) / τ_s, ±δ̇_max)

The plant's derivative function (``vehicle.TwoTrackModel``) evaluates these same equations
inline, in plain floats, for speed; the functions here are their reference statement and
are used by the simulator for clipping and by the tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ActuatorLimits:
    """Limits in SI units (rad, rad/s, N·m)."""

    max_steer_front_rad: float
    max_steer_rear_rad: float
    max_steer_rate_front_rad_s: float
    max_steer_rate_rear_rad_s: float
    motor_torque_max_nm: float


def motor_transfer_function(tau_s: float) -> tuple[list[float], list[float]]:
    """(numerator, denominator) of eq. (32) in descending powers of s."""
    return [1.0], [2.0 * tau_s * tau_s, 2.0 * tau_s, 1.0]


def motor_state_space(tau_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, C, D) of eq. (32) with state [T, Ṫ], input T_md, output T."""
    a = np.array([[0.0, 1.0], [-1.0 / (2.0 * tau_s * tau_s), -1.0 / tau_s]])
    b = np.array([[0.0], [1.0 / (2.0 * tau_s * tau_s)]])
    c = np.array([[1.0, 0.0]])
    d = np.array([[0.0]])
    return a, b, c, d


def motor_derivative(
    torque: float, torque_rate: float, torque_cmd: float, tau_s: float
) -> tuple[float, float]:
    """(Ṫ, T̈) of one motor, eq. (32); N·m/s and N·m/s²."""
    return torque_rate, (torque_cmd - torque - 2.0 * tau_s * torque_rate) / (2.0 * tau_s * tau_s)


def steer_derivative(angle: float, angle_cmd: float, tau_s: float, rate_max: float) -> float:
    """δ̇ (rad/s) of a rate-limited first-order steering actuator; ``angle_cmd`` already
    clipped to the angle limits."""
    rate = (angle_cmd - angle) / tau_s
    return min(max(rate, -rate_max), rate_max)


def check_finite_commands(
    steer_front: float, steer_rear: float, wheel_torque: np.ndarray | list[float]
) -> tuple[float, float, tuple[float, float, float, float]]:
    """Convert the commands to floats; raise ``ValueError`` on a non-finite value or a wheel
    torque array that is not of length 4."""
    torques = tuple(float(t) for t in np.asarray(wheel_torque, dtype=float).ravel())
    if len(torques) != 4:
        raise ValueError(f"wheel_torque_cmd: expected 4 values (FL FR RL RR), got {len(torques)}")
    sf, sr = float(steer_front), float(steer_rear)
    for name, value in (("steer_front_cmd", sf), ("steer_rear_cmd", sr)):
        if not math.isfinite(value):
            raise ValueError(f"{name}: must be finite, got {value!r}")
    if not all(math.isfinite(t) for t in torques):
        raise ValueError(f"wheel_torque_cmd: every element must be finite, got {torques}")
    return sf, sr, torques  # type: ignore[return-value]


def clip_commands(
    steer_front: float,
    steer_rear: float,
    wheel_torque: tuple[float, float, float, float],
    limits: ActuatorLimits,
) -> tuple[tuple[float, ...], tuple[str, ...]]:
    """Clip finite commands to the actuator limits.

    Returns ((δf, δr, T_FL, T_FR, T_RL, T_RR), names of the channels that were clipped).
    """
    clipped: list[str] = []

    def sat(value: float, lim: float, name: str) -> float:
        if value > lim:
            clipped.append(name)
            return lim
        if value < -lim:
            clipped.append(name)
            return -lim
        return value

    out = (
        sat(steer_front, limits.max_steer_front_rad, "steer_front"),
        sat(steer_rear, limits.max_steer_rear_rad, "steer_rear"),
        *(
            sat(t, limits.motor_torque_max_nm, f"wheel_torque[{i}]")
            for i, t in enumerate(wheel_torque)
        ),
    )
    return out, tuple(clipped)
