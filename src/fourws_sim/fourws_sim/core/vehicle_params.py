"""Reads the plant's vehicle, tyre and actuator parameters from the car file.

:class:`VehicleParams` is the frozen dataclass (SI, except the ``*_deg`` fields people edit)
with the quantities derived from it (static loads, tyre coefficients, static cornering
stiffness, relaxation length, actuator limits, wheel positions); :func:`load_vehicle_params`
reads a car file (:mod:`fourws_common.vehicle_info`, default the paper's car) and checks its
recorded derived values (docs/plant.md, "The car files"). The model that uses them is
:class:`fourws_sim.core.vehicle.TwoTrackModel`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from fourws_common.params import from_mapping, param
from fourws_common.vehicle_info import field_range, read_vehicle_file, vehicle_path
from fourws_common.wheels import Wheel
from fourws_sim.core.actuators import ActuatorLimits
from fourws_sim.core.tyre import TyreCoefficients, cornering_stiffness

SIGMA_MIN_M = 0.05
"""Floor of the lateral relaxation length, m (keeps the slip lag resolved by a 1 ms substep)."""

RECORDED_KEYS = (
    "cornering_stiffness_front_static_n_per_rad",
    "cornering_stiffness_rear_static_n_per_rad",
    "relaxation_length_front_static_m",
    "relaxation_length_rear_static_m",
)
"""Keys of a car file that record derived values (not inputs) for the controllers; checked
against the file's own inputs on load (:meth:`VehicleParams.recorded_values`)."""


@dataclass(frozen=True)
class VehicleParams:
    """Vehicle, tyre and actuator parameters (SI, except the *_deg fields people edit)."""

    mass_kg: float = param(750.0, "total vehicle mass (Table 5)", **field_range("mass_kg"))
    yaw_inertia_kg_m2: float = param(750.0, "yaw moment of inertia about the CG (Table 5)",
                                     **field_range("yaw_inertia_kg_m2"))
    wheelbase_m: float = param(2.35, "wheelbase L (Table 5)", lo=0.5, hi=6.0, unit="m")
    cg_to_front_axle_m: float = param(1.10, "CG to front axle a (Table 5)",
                                      **field_range("cg_to_front_axle_m"))
    cg_to_rear_axle_m: float = param(1.25, "CG to rear axle b (Table 5)",
                                     **field_range("cg_to_rear_axle_m"))
    cg_height_m: float = param(0.54, "CG height h (Table 5)", **field_range("cg_height_m"))
    track_width_front_m: float = param(1.30, "front track width B_f",
                                       **field_range("track_width_front_m"))
    track_width_rear_m: float = param(1.30, "rear track width B_r",
                                      **field_range("track_width_rear_m"))
    wheel_radius_m: float = param(0.27, "effective rolling radius (Table 5)",
                                  **field_range("wheel_radius_m"))
    wheel_inertia_kg_m2: float = param(
        0.8, "spin inertia of wheel, tyre and motor rotor", lo=0.05, hi=20.0, unit="kg*m^2"
    )
    roll_stiffness_front_share: float = param(0.55, "front share of the total roll stiffness",
                                              **field_range("roll_stiffness_front_share"))
    load_transfer_time_constant_s: float = param(
        0.08, "lag of the accelerations that drive load transfer", lo=0.005, hi=1.0, unit="s"
    )
    gravity_mps2: float = param(9.81, "gravitational acceleration", **field_range("gravity_mps2"))
    air_density_kg_m3: float = param(1.2, "air density", lo=0.0, hi=2.0, unit="kg/m^3")
    drag_coefficient: float = param(0.32, "aerodynamic drag coefficient c_d", lo=0.0, hi=2.0,
                                    unit="1")
    frontal_area_m2: float = param(1.9, "frontal area A", lo=0.0, hi=10.0, unit="m^2")
    rolling_resistance_coeff: float = param(
        0.012, "rolling resistance coefficient f_r", lo=0.0, hi=0.1, unit="1"
    )
    rolling_resistance_speed_mps: float = param(
        0.5, "speed scale of the tanh that fades rolling resistance at standstill",
        lo=0.01, hi=5.0, unit="m/s",
    )
    tyre_nominal_load_n: float = param(2000.0, "tyre nominal load F_z0",
                                       **field_range("tyre_nominal_load_n"))
    tyre_cornering_coeff_front: float = param(
        17.73, "p_Ky1 of the front tyres (K_alpha scale)", lo=1.0, hi=100.0, unit="1"
    )
    tyre_cornering_coeff_rear: float = param(
        20.65, "p_Ky1 of the rear tyres (K_alpha scale)", lo=1.0, hi=100.0, unit="1"
    )
    tyre_cornering_load_factor: float = param(
        2.0, "p_Ky2: K_alpha peaks at F_z = p_Ky2 F_z0", **field_range("tyre_cornering_load_factor")
    )
    tyre_long_stiffness_per_load: float = param(
        17.0, "longitudinal slip stiffness over load c_kappa = K_kappa/F_z", lo=1.0, hi=60.0,
        unit="1",
    )
    tyre_friction_load_sensitivity: float = param(
        0.0, "p_D2: peak friction falls by this fraction per F_z0 of load above F_z0",
        lo=-0.5, hi=0.0, unit="1",
    )
    tyre_shape_lateral: float = param(1.3, "Magic Formula C_y", **field_range("tyre_shape_lateral"))
    tyre_curvature_lateral: float = param(-1.0, "Magic Formula E_y",
                                          **field_range("tyre_curvature_lateral"))
    tyre_shape_longitudinal: float = param(1.65, "Magic Formula C_x", lo=1.01, hi=1.99, unit="1")
    tyre_curvature_longitudinal: float = param(0.0, "Magic Formula E_x", lo=-10.0, hi=0.99,
                                               unit="1")
    tyre_relaxation_peak_over_radius: float = param(
        1.2, "p_Ty1: peak lateral relaxation length over the wheel radius (0: no lag)",
        lo=0.0, hi=10.0, unit="1",
    )
    tyre_relaxation_load_factor: float = param(
        2.5, "p_Ty2: the relaxation length peaks at F_z = p_Ty2 F_z0", lo=0.2, hi=10.0, unit="1"
    )
    slip_speed_min_mps: float = param(2.5, "floor of the slip denominators max(|v_x|, v_min)",
                                      **field_range("slip_speed_min_mps"))
    motor_time_constant_s: float = param(
        0.02, "in-wheel motor tau of eq. (32) (Table 5)", lo=0.001, hi=1.0, unit="s"
    )
    motor_torque_max_nm: float = param(500.0, "in-wheel motor torque limit (each, +/-)",
                                       **field_range("motor_torque_max_nm"))
    steer_front_time_constant_s: float = param(0.02, "front steering actuator first-order lag",
                                               **field_range("steer_front_time_constant_s"))
    steer_rear_time_constant_s: float = param(0.02, "rear steering actuator first-order lag",
                                              **field_range("steer_rear_time_constant_s"))
    max_steer_front_deg: float = param(30.0, "front road-wheel angle limit (eq. 20)",
                                       **field_range("max_steer_front_deg"))
    max_steer_rear_deg: float = param(10.0, "rear road-wheel angle limit (eq. 20)",
                                      **field_range("max_steer_rear_deg"))
    max_steer_rate_front_deg_s: float = param(
        80.0, "front road-wheel angle rate limit", lo=1.0, hi=1000.0, unit="deg/s"
    )
    max_steer_rate_rear_deg_s: float = param(
        60.0, "rear road-wheel angle rate limit", lo=1.0, hi=1000.0, unit="deg/s"
    )

    def __post_init__(self) -> None:
        total = self.cg_to_front_axle_m + self.cg_to_rear_axle_m
        if abs(total - self.wheelbase_m) > 1e-3:
            raise ValueError(
                f"cg_to_front_axle_m + cg_to_rear_axle_m = {total:.4f} m must equal "
                f"wheelbase_m = {self.wheelbase_m:.4f} m"
            )

    # --- derived quantities -------------------------------------------------------------

    @property
    def static_wheel_loads_n(self) -> np.ndarray:
        """Static vertical loads (4,), N, FL FR RL RR."""
        w = self.mass_kg * self.gravity_mps2
        front = 0.5 * w * self.cg_to_rear_axle_m / self.wheelbase_m
        rear = 0.5 * w * self.cg_to_front_axle_m / self.wheelbase_m
        return np.array([front, front, rear, rear])

    def tyre(self, axle: str = "front") -> TyreCoefficients:
        """Tyre coefficients of the ``"front"`` or ``"rear"`` tyres, or of all four wheels
        (``"all"``: p_Ky1 as an array FL FR RL RR)."""
        f, r = self.tyre_cornering_coeff_front, self.tyre_cornering_coeff_rear
        coeff: float | np.ndarray = {"front": f, "rear": r, "all": np.array([f, f, r, r])}[axle]
        return TyreCoefficients(
            nominal_load_n=self.tyre_nominal_load_n,
            cornering_coeff=coeff,
            cornering_load_factor=self.tyre_cornering_load_factor,
            long_stiffness_per_load=self.tyre_long_stiffness_per_load,
            friction_load_sensitivity=self.tyre_friction_load_sensitivity,
            shape_lat=self.tyre_shape_lateral,
            curvature_lat=self.tyre_curvature_lateral,
            shape_long=self.tyre_shape_longitudinal,
            curvature_long=self.tyre_curvature_longitudinal,
        )

    def static_cornering_stiffness(self) -> tuple[float, float]:
        """Per-tyre cornering stiffness (front, rear) at static load, N/rad: the C_cf, C_cr
        of the linear single-track model."""
        loads = self.static_wheel_loads_n
        return (
            float(cornering_stiffness(loads[Wheel.FL], self.tyre("front"))),
            float(cornering_stiffness(loads[Wheel.RL], self.tyre("rear"))),
        )

    def relaxation_length_m(self, fz_n: np.ndarray | float) -> np.ndarray:
        """Lateral relaxation length σ (m) at wheel load ``fz_n`` (N), MF 5.2 σ_α0 floored at
        :data:`SIGMA_MIN_M`; 0 where the lag is off (p_Ty1 = 0)."""
        if self.tyre_relaxation_peak_over_radius == 0.0:
            return np.zeros_like(np.asarray(fz_n, dtype=float))
        sigma = (self.tyre_relaxation_peak_over_radius * self.wheel_radius_m
                 * np.sin(2.0 * np.arctan(np.asarray(fz_n, dtype=float)
                                          / (self.tyre_relaxation_load_factor
                                             * self.tyre_nominal_load_n))))
        return np.maximum(sigma, SIGMA_MIN_M)

    def recorded_values(self) -> dict[str, float]:
        """The derived values a car file records (:data:`RECORDED_KEYS`): per-tyre cornering
        stiffness and relaxation length at static load, front and rear."""
        c_f, c_r = self.static_cornering_stiffness()
        sig_f, sig_r = self.relaxation_length_m(self.static_wheel_loads_n[[Wheel.FL, Wheel.RL]])
        return dict(zip(RECORDED_KEYS, (c_f, c_r, float(sig_f), float(sig_r)), strict=True))

    def understeer_gradient(self) -> float:
        """K_us = m/L (b/(2C_f) − a/(2C_r)) of the linear single-track model, rad/(m/s²)."""
        cf, cr = self.static_cornering_stiffness()
        return (self.mass_kg / self.wheelbase_m) * (
            self.cg_to_rear_axle_m / (2.0 * cf) - self.cg_to_front_axle_m / (2.0 * cr)
        )

    def actuator_limits(self) -> ActuatorLimits:
        """Actuator limits in SI units."""
        return ActuatorLimits(
            max_steer_front_rad=math.radians(self.max_steer_front_deg),
            max_steer_rear_rad=math.radians(self.max_steer_rear_deg),
            max_steer_rate_front_rad_s=math.radians(self.max_steer_rate_front_deg_s),
            max_steer_rate_rear_rad_s=math.radians(self.max_steer_rate_rear_deg_s),
            motor_torque_max_nm=self.motor_torque_max_nm,
        )

    def wheel_positions_m(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """((x_i), (y_i)) of the wheel centres in the body frame, m, FL FR RL RR."""
        a, b = self.cg_to_front_axle_m, self.cg_to_rear_axle_m
        hf, hr = 0.5 * self.track_width_front_m, 0.5 * self.track_width_rear_m
        return (a, a, -b, -b), (hf, -hf, hr, -hr)


def load_vehicle_params(
    path: Path | str | None = None, overrides: Mapping[str, Any] | None = None
) -> VehicleParams:
    """VehicleParams from a car file (a shipped name or a path; default the paper's car) with
    ``overrides`` merged over.

    The recorded keys (:data:`RECORDED_KEYS`) are checked against the file's own inputs
    (within 0.5 %) and then dropped; with overrides the recorded values describe the base
    file only. Raises ``ValueError`` naming the file and the offending key.
    """
    where = vehicle_path(path)
    values = read_vehicle_file(where)
    missing = [f.name for f in fields(VehicleParams) if f.name not in values]
    if missing:                       # no silent default: the file is the car's one owner
        raise ValueError(f"{where}: missing vehicle key(s) {missing}")
    recorded = {k: values.pop(k) for k in RECORDED_KEYS if k in values}
    try:
        base = from_mapping(VehicleParams, values)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
    actual = base.recorded_values()
    for key, value in recorded.items():
        if abs(float(value) - actual[key]) > 0.005 * abs(actual[key]):
            raise ValueError(
                f"{where}: {key}: the file records {value} but its own inputs give "
                f"{actual[key]:.6g}; update the recorded value"
            )
    if overrides:
        values.update(overrides)
        return from_mapping(VehicleParams, values)
    return base
