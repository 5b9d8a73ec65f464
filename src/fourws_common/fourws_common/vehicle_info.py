"""The car description: one file read by every node (docs/graph.md, "One car file").

A car file (``fourws_common/config/vehicles/<name>.yaml``, or any path) is the flat mapping
of the plant's :class:`fourws_sim.core.vehicle_params.VehicleParams` fields plus the derived
values it records (static cornering stiffness and relaxation length, checked by the plant
on load). The plant reads all of it. The controllers read :class:`VehicleInfo`, the part a
controller on a real car knows, and :func:`node_vehicle_values` turns it into each node's
parameter defaults: a node's params files (a preset, a mismatch study's overrides) still
win over them, so a model mismatch stays an explicit override. Pure Python, no ROS.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fourws_common.params import check_field, read_yaml_file

#: The car every node uses when none is given: the paper's (Table 5).
DEFAULT_VEHICLE = "paper"


def _spec(description: str, *, lo: float, hi: float, unit: str) -> Any:
    """A required field with its closed range (no default: the car file is the one owner
    of every value)."""
    return dataclasses.field(metadata={"description": description, "lo": lo, "hi": hi,
                                       "unit": unit})


@dataclasses.dataclass(frozen=True)
class VehicleInfo:
    """The constants of a car that its controllers use (SI, except the ``*_deg`` fields)."""

    mass_kg: float = _spec("total mass m", lo=100.0, hi=5000.0, unit="kg")
    yaw_inertia_kg_m2: float = _spec("yaw inertia I_z", lo=10.0, hi=20000.0,
                                     unit="kg*m^2")
    cg_to_front_axle_m: float = _spec("CG to front axle a", lo=0.1, hi=5.0, unit="m")
    cg_to_rear_axle_m: float = _spec("CG to rear axle b", lo=0.1, hi=5.0, unit="m")
    cg_height_m: float = _spec("CG height h", lo=0.0, hi=2.0, unit="m")
    track_width_front_m: float = _spec("front track B_f", lo=0.5, hi=3.0, unit="m")
    track_width_rear_m: float = _spec("rear track B_r", lo=0.5, hi=3.0, unit="m")
    wheel_radius_m: float = _spec("effective rolling radius", lo=0.1, hi=1.0, unit="m")
    roll_stiffness_front_share: float = _spec("front share of roll stiffness", lo=0.0,
                                              hi=1.0, unit="1")
    gravity_mps2: float = _spec("gravitational acceleration", lo=9.7, hi=9.9,
                                unit="m/s^2")
    tyre_shape_lateral: float = _spec("Magic Formula C_y", lo=1.01, hi=1.99, unit="1")
    tyre_curvature_lateral: float = _spec("Magic Formula E_y", lo=-10.0, hi=0.99,
                                          unit="1")
    tyre_nominal_load_n: float = _spec("tyre nominal load F_z0", lo=100.0, hi=20000.0,
                                       unit="N")
    tyre_cornering_load_factor: float = _spec("p_Ky2: K_alpha peaks at F_z = p_Ky2 F_z0",
                                              lo=0.2, hi=10.0, unit="1")
    cornering_stiffness_front_static_n_per_rad: float = _spec(
        "per-tyre cornering stiffness at static load, front (recorded)", lo=1000.0,
        hi=500000.0, unit="N/rad")
    cornering_stiffness_rear_static_n_per_rad: float = _spec(
        "per-tyre cornering stiffness at static load, rear (recorded)", lo=1000.0,
        hi=500000.0, unit="N/rad")
    relaxation_length_front_static_m: float = _spec(
        "lateral relaxation length at static load, front (recorded)", lo=0.0, hi=2.0,
        unit="m")
    relaxation_length_rear_static_m: float = _spec(
        "lateral relaxation length at static load, rear (recorded)", lo=0.0, hi=2.0,
        unit="m")
    motor_torque_max_nm: float = _spec("torque limit of each in-wheel motor", lo=1.0,
                                       hi=5000.0, unit="N*m")
    steer_front_time_constant_s: float = _spec("front steering lag", lo=0.001, hi=1.0,
                                               unit="s")
    steer_rear_time_constant_s: float = _spec("rear steering lag", lo=0.001, hi=1.0,
                                              unit="s")
    max_steer_front_deg: float = _spec("front road-wheel angle limit", lo=1.0, hi=60.0,
                                       unit="deg")
    max_steer_rear_deg: float = _spec("rear road-wheel angle limit", lo=0.0, hi=60.0,
                                      unit="deg")
    slip_speed_min_mps: float = _spec("floor of a slip's speed denominator", lo=0.1, hi=10.0,
                                      unit="m/s")

    @property
    def track_width_m(self) -> float:
        """B = (B_f + B_r)/2: the one track of the single-track controllers and of the
        allocation's eq. (27)-(31), which take B_f = B_r."""
        return 0.5 * (self.track_width_front_m + self.track_width_rear_m)


def field_range(name: str) -> dict[str, Any]:
    """``lo``, ``hi`` and ``unit`` of the :class:`VehicleInfo` key ``name``: the one owner of
    the ranges the plant's ``VehicleParams`` shares with the controllers."""
    f = {f.name: f for f in dataclasses.fields(VehicleInfo)}[name]
    return {k: f.metadata[k] for k in ("lo", "hi", "unit")}


def vehicles_dir() -> Path:
    """``fourws_common/config/vehicles`` (source tree or installed share)."""
    from fourws_common.resources import config_dir

    return config_dir("fourws_common") / "vehicles"


def list_vehicles() -> list[str]:
    """Names of the shipped car files."""
    return sorted(p.stem for p in vehicles_dir().glob("*.yaml"))


def vehicle_path(name_or_path: str | Path | None = None) -> Path:
    """The car file of a shipped name, or the given path ("" or ``None``: the default car).
    ``ValueError`` names the known cars or the missing file."""
    from fourws_common.resources import named_yaml

    return named_yaml(name_or_path or DEFAULT_VEHICLE, vehicles_dir(), "vehicle")


def read_vehicle_file(name_or_path: str | Path | None = None) -> dict[str, Any]:
    """The flat mapping of a car file, plain or in ROS params-file form
    (``node: {ros__parameters: {...}}``). ``ValueError`` names the file."""
    path = vehicle_path(name_or_path)
    data = read_yaml_file(path) or {}
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a mapping at the top level")
    sections = [v for v in data.values() if isinstance(v, dict) and "ros__parameters" in v]
    if sections:
        flat: dict[str, Any] = {}
        for s in sections:
            flat.update(s["ros__parameters"] or {})
        return flat
    return dict(data)


def load_vehicle_info(name_or_path: str | Path | None = None) -> VehicleInfo:
    """The controllers' part of a car file. Every :class:`VehicleInfo` key must be in it
    (the plant's other keys are left to the plant); ``ValueError`` names the file and key."""
    path = vehicle_path(name_or_path)
    values = read_vehicle_file(path)
    keys = [f.name for f in dataclasses.fields(VehicleInfo)]
    missing = [k for k in keys if k not in values]
    if missing:
        raise ValueError(f"{path}: missing vehicle key(s) {missing}")
    try:
        return VehicleInfo(**{k: check_field(VehicleInfo, k, values[k]) for k in keys})
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


def _mpc(v: VehicleInfo) -> dict[str, Any]:
    same = ("mass_kg", "yaw_inertia_kg_m2", "cg_to_front_axle_m", "cg_to_rear_axle_m",
            "cg_height_m", "roll_stiffness_front_share", "tyre_nominal_load_n",
            "tyre_cornering_load_factor", "cornering_stiffness_front_static_n_per_rad",
            "cornering_stiffness_rear_static_n_per_rad", "gravity_mps2", "tyre_shape_lateral",
            "tyre_curvature_lateral", "steer_front_time_constant_s",
            "steer_rear_time_constant_s", "max_steer_front_deg", "max_steer_rear_deg")
    return {**{k: getattr(v, k) for k in same}, "track_width_m": v.track_width_m,
            "relaxation_length_front_m": v.relaxation_length_front_static_m,
            "relaxation_length_rear_m": v.relaxation_length_rear_static_m}


def _speed_pid(v: VehicleInfo) -> dict[str, Any]:
    total = 4.0 * v.motor_torque_max_nm
    return {"mass_kg": v.mass_kg, "wheel_radius_m": v.wheel_radius_m,
            "max_total_torque_nm": total, "min_total_torque_nm": -total}


def _allocator(v: VehicleInfo) -> dict[str, Any]:
    same = ("wheel_radius_m", "motor_torque_max_nm", "mass_kg", "cg_to_front_axle_m",
            "cg_to_rear_axle_m", "cg_height_m", "roll_stiffness_front_share",
            "slip_speed_min_mps", "gravity_mps2")
    return {**{k: getattr(v, k) for k in same}, "track_width_m": v.track_width_m}


#: node name -> its parameters taken from the car (the node's own file sets none of them)
NODE_VALUES: dict[str, Callable[[VehicleInfo], dict[str, Any]]] = {
    "mpc_node": _mpc,
    "speed_pid_node": _speed_pid,
    "allocator_node": _allocator,
}


def node_vehicle_values(node: str, vehicle: VehicleInfo) -> dict[str, Any]:
    """The parameter defaults ``node`` takes from the car (empty for a node that takes
    none)."""
    make = NODE_VALUES.get(node)
    return make(vehicle) if make is not None else {}
