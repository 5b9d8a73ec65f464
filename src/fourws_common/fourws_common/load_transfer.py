"""Computes the quasi-static wheel loads of measured accelerations: the loads every controller
assumes (the allocator's tyre estimate, the MPC's friction-aware prediction and μ estimate;
docs/lower-layer.md, "Tyre data").

A rigid body; the roll stiffness splits the lateral transfer between the axles::

    F_z,front = m g b/(2L) − m h a_x/(2L),   F_z,rear = m g a/(2L) + m h a_x/(2L)
    F_z,FL/FR = F_z,front ∓ χ_f m h a_y / B_f,   F_z,RL/RR = F_z,rear ∓ (1−χ_f) m h a_y / B_r

clipped at 0 (a wheel in the air), FL FR RL RR, a_x and a_y in the ISO body frame (m/s²).
With χ_f the front roll-stiffness share this is the plant's own transfer in steady state (its
transient lags by the load-transfer time constant), and while no wheel is clipped the four
loads sum to m g. Pure Python, no ROS.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class LoadGeometry:
    """The car's constants behind its loads (SI; names as in the car file)."""

    mass_kg: float
    cg_to_front_axle_m: float
    cg_to_rear_axle_m: float
    cg_height_m: float
    track_width_front_m: float
    track_width_rear_m: float
    roll_stiffness_front_share: float
    gravity_mps2: float


def wheel_loads(ax: float, ay: float, g: LoadGeometry) -> tuple[float, float, float, float]:
    """(F_z,FL, F_z,FR, F_z,RL, F_z,RR), N, of the module docstring."""
    return loads(ax, ay, g.mass_kg, g.cg_to_front_axle_m, g.cg_to_rear_axle_m, g.cg_height_m,
                 g.track_width_front_m, g.track_width_rear_m, g.roll_stiffness_front_share,
                 g.gravity_mps2)


def loads(ax: float, ay: float, mass_kg: float, a_m: float, b_m: float, h_m: float,
          track_front_m: float, track_rear_m: float, chi_front: float, gravity_mps2: float
          ) -> tuple[float, float, float, float]:
    """:func:`wheel_loads` on plain floats (what a compiled caller can take: the MPC's
    prediction compiles this function)."""
    length = a_m + b_m
    w = mass_kg * gravity_mps2
    mh = mass_kg * h_m
    dl = 0.5 * mh * ax / length
    df = chi_front * mh * ay / track_front_m
    dr = (1.0 - chi_front) * mh * ay / track_rear_m
    f, r = 0.5 * w * b_m / length - dl, 0.5 * w * a_m / length + dl
    return max(f - df, 0.0), max(f + df, 0.0), max(r - dr, 0.0), max(r + dr, 0.0)
