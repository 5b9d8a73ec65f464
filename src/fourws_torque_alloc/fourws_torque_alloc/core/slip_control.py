"""Limits wheel slip after the allocation, as a car's ABS and traction control do.

Beyond the paper (its allocation, eq. 25-31, assumes every wheel delivers its torque; see
docs/lower-layer.md, "Wheel-slip limiter"). Each wheel's longitudinal slip from the measured
wheel speed and the car's motion::

    v_i = (v_x − r y_i) cos δ_i + (v_y + r x_i) sin δ_i      (wheel centre along its heading)
    κ_i = (ω_i R − v_i) / max(|v_i|, v_min)

A torque that pushes its wheel's slip beyond κ_on in its own direction (a brake torque with
κ_i < −κ_on, a drive torque with κ_i > κ_on) is scaled by

    s_i = clip((κ_off − |κ_i|) / (κ_off − κ_on), 0, 1),

so it falls to zero at κ_off; a wheel spinning against the car's motion (ω_i v_i < 0) gets no
torque in that direction. The rear axle brakes select-low, as ABS does: once a rear wheel is
limited under braking, the other rear wheel brakes no harder, so the axle that holds the car's
yaw keeps its lateral grip on split μ; the front wheels are limited one by one. Below v_min
(standstill) nothing is limited. The tyre's longitudinal force peaks at |κ| of about
0.05-0.15 and falls slowly beyond, so a wheel held near κ_on keeps most of its braking force
and, unlike a locked wheel, its lateral force. Pure numpy, SI.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fourws_common.wheels import Wheel


@dataclass(frozen=True)
class WheelMotion:
    """What the limiter reads from a state: wheel spin rates (rad/s, FL FR RL RR), body
    velocities (m/s), yaw rate (rad/s) and road-wheel angles (rad)."""

    wheel_speed_rad_s: tuple[float, float, float, float]
    vx_mps: float
    vy_mps: float
    yaw_rate_rad_s: float
    steer_front_rad: float
    steer_rear_rad: float

    @classmethod
    def of(cls, state: object) -> WheelMotion:
        """From a state message or sample (attributes wheel_speed, vx, vy, yaw_rate,
        steer_front, steer_rear)."""
        w = tuple(float(v) for v in state.wheel_speed)
        return cls(w, float(state.vx), float(state.vy), float(state.yaw_rate),
                   float(state.steer_front), float(state.steer_rear))


#: per wheel (``Wheel`` order): whether it is steered by the front angle
_FRONT = tuple(w in (Wheel.FL, Wheel.FR) for w in Wheel)


def wheel_slip(m: WheelMotion, a_m: float, b_m: float, track_m: float, radius_m: float,
               v_min_mps: float) -> tuple[np.ndarray, np.ndarray]:
    """(κ (4,), v (4,) m/s): each wheel's longitudinal slip and its centre's speed along its
    heading (module docstring)."""
    # per wheel, in the order of ``Wheel`` (FL FR RL RR): position and road-wheel angle
    x = (a_m, a_m, -b_m, -b_m)
    y = (0.5 * track_m, -0.5 * track_m, 0.5 * track_m, -0.5 * track_m)
    d = tuple(m.steer_front_rad if front else m.steer_rear_rad for front in _FRONT)
    v = [(m.vx_mps - m.yaw_rate_rad_s * y[i]) * math.cos(d[i])
         + (m.vy_mps + m.yaw_rate_rad_s * x[i]) * math.sin(d[i]) for i in range(len(Wheel))]
    kappa = [(m.wheel_speed_rad_s[i] * radius_m - v[i]) / max(abs(v[i]), v_min_mps)
             for i in range(len(Wheel))]
    return np.array(kappa), np.array(v)


def limit_slip(torque_nm: np.ndarray, m: WheelMotion, *, a_m: float, b_m: float,
               track_m: float, radius_m: float, kappa_on: float, kappa_off: float,
               v_min_mps: float) -> tuple[np.ndarray, np.ndarray]:
    """(torques (4,) N·m, limited (4,) bool): ``torque_nm`` scaled wheel by wheel (module
    docstring). Inputs that are not finite leave the torques as they are."""
    t = np.array(torque_nm, dtype=float)
    limited = np.zeros(4, dtype=bool)
    values = (*m.wheel_speed_rad_s, m.vx_mps, m.vy_mps, m.yaw_rate_rad_s, m.steer_front_rad,
              m.steer_rear_rad)
    if not all(math.isfinite(v) for v in values) or abs(m.vx_mps) < v_min_mps:
        return t, limited
    kappa, v = wheel_slip(m, a_m, b_m, track_m, radius_m, v_min_mps)
    for i in range(4):
        if t[i] == 0.0:
            continue
        along = math.copysign(1.0, t[i]) * math.copysign(1.0, v[i])  # +1: drives, −1: brakes
        slip = kappa[i] * math.copysign(1.0, v[i])                     # > 0: spins faster
        if m.wheel_speed_rad_s[i] * v[i] < 0.0 and along < 0.0:
            s = 0.0                           # turning backwards: no more brake torque
        elif along * slip > kappa_on:
            s = min(1.0, max(0.0, (kappa_off - abs(slip)) / (kappa_off - kappa_on)))
        else:
            continue
        t[i] *= s
        limited[i] = True
    rl, rr = Wheel.RL, Wheel.RR
    if (limited[rl] or limited[rr]) and t[rl] * v[rl] < 0.0 and t[rr] * v[rr] < 0.0:
        low = min(abs(t[rl]), abs(t[rr]))          # select-low: both at the weaker wheel
        for i in (rl, rr):
            if abs(t[i]) > low:
                t[i] = math.copysign(low, t[i])
                limited[i] = True
    return t, limited
