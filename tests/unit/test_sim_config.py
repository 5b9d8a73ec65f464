"""The car file ↔ VehicleParams, ranges and cross-field rules."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml

from fourws_common.vehicle_info import read_vehicle_file
from fourws_sim.core.vehicle_params import (
    RECORDED_KEYS,
    VehicleParams,
    load_vehicle_params,
)

ROOT = Path(__file__).resolve().parents[2]
CORE = ROOT / "src" / "fourws_sim" / "fourws_sim" / "core"


def test_vehicle_yaml_loads_and_the_dataclass_defaults_mirror_it():
    loaded = load_vehicle_params()
    raw = read_vehicle_file()
    names = {f.name for f in dataclasses.fields(VehicleParams)}
    assert set(raw) - set(RECORDED_KEYS) == names, "vehicle.yaml must set every field"
    assert loaded == VehicleParams()


def test_table5_values():
    p = load_vehicle_params()
    assert (p.mass_kg, p.wheelbase_m, p.cg_to_front_axle_m, p.cg_to_rear_axle_m) == (
        750.0, 2.35, 1.10, 1.25)
    assert (p.wheel_radius_m, p.cg_height_m, p.yaw_inertia_kg_m2) == (0.27, 0.54, 750.0)
    assert p.motor_time_constant_s == 0.02
    assert p.static_wheel_loads_n.sum() == pytest.approx(p.mass_kg * p.gravity_mps2)


@pytest.mark.parametrize(
    "key, value",
    [("mass_kg", -5.0), ("cg_height_m", 3.0), ("roll_stiffness_front_share", 1.5),
     ("tyre_shape_lateral", 2.5), ("max_steer_front_deg", 0.0)],
)
def test_out_of_range_value_raises_naming_the_key(key, value):
    with pytest.raises(ValueError, match=key):
        load_vehicle_params(overrides={key: value})


def test_unknown_key_and_inconsistent_geometry_raise():
    with pytest.raises(ValueError, match="no_such_key"):
        load_vehicle_params(overrides={"no_such_key": 1.0})
    with pytest.raises(ValueError, match="wheelbase_m"):
        load_vehicle_params(overrides={"cg_to_front_axle_m": 1.3})


def test_a_stale_recorded_cornering_stiffness_is_caught(tmp_path):
    raw = read_vehicle_file()
    raw["tyre_cornering_coeff_front"] = 15.0
    path = tmp_path / "vehicle.yaml"
    path.write_text(yaml.safe_dump(raw), encoding="utf-8")
    with pytest.raises(ValueError, match="cornering_stiffness_front_static_n_per_rad"):
        load_vehicle_params(path)


def test_ros_params_file_form_is_accepted(tmp_path):
    raw = read_vehicle_file()
    path = tmp_path / "vehicle.yaml"
    path.write_text(yaml.safe_dump({"plant_node": {"ros__parameters": raw}}), encoding="utf-8")
    assert load_vehicle_params(path) == VehicleParams()


def test_unreadable_or_broken_vehicle_yaml_names_the_file(tmp_path):
    bad = tmp_path / "vehicle.yaml"
    bad.write_text("mass_kg: 750.0\nwheelbase_m: [2.35\n", encoding="utf-8")
    with pytest.raises(ValueError, match=r"vehicle\.yaml: YAML syntax error at line 3"):
        load_vehicle_params(bad)
    with pytest.raises(ValueError, match="missing.yaml"):
        load_vehicle_params(tmp_path / "missing.yaml")


def test_overrides_apply():
    p = load_vehicle_params(overrides={"mass_kg": 800.0, "track_width_rear_m": 1.35})
    assert p.mass_kg == 800.0 and p.track_width_rear_m == 1.35
