"""One car file, one owner per vehicle constant: every controller takes the car's values
under the plant's names, its own params files set none of them, so a model mismatch is
always an explicit override (issue 41, "One car file")."""

import dataclasses

import pytest
import yaml

from fourws_bringup.core.configs import (
    core_values,
    list_controllers,
    load_allocator_config,
    load_mpc_config,
    load_pid_config,
    node_values,
)
from fourws_common.vehicle_info import (
    VehicleInfo,
    field_range,
    list_vehicles,
    load_vehicle_info,
    node_vehicle_values,
    read_vehicle_file,
)
from fourws_mpc.core.config import MpcConfig
from fourws_sim.core.vehicle_params import VehicleParams, load_vehicle_params
from fourws_torque_alloc.core.allocation import AllocatorConfig
from fourws_torque_alloc.core.pid import SpeedPidConfig

PLANT = read_vehicle_file()
PARAMS = load_vehicle_params()
CONTROLLER_NODES = ("mpc_node", "speed_pid_node", "allocator_node")
#: constants several nodes use, under the plant's names (issue 16)
SHARED = ("mass_kg", "yaw_inertia_kg_m2", "cg_to_front_axle_m", "cg_to_rear_axle_m",
          "wheel_radius_m", "motor_torque_max_nm", "cornering_stiffness_front_static_n_per_rad",
          "cornering_stiffness_rear_static_n_per_rad", "max_steer_front_deg",
          "max_steer_rear_deg")


@pytest.mark.parametrize("controller", list_controllers())
@pytest.mark.parametrize("node", CONTROLLER_NODES)
def test_every_key_a_controller_shares_with_the_plant_has_the_plants_value(node, controller):
    values = core_values(node_values(node, controller))
    shared = sorted(set(values) & set(PLANT))
    assert shared, f"{node} shares no constant with vehicle.yaml"
    for key in shared:
        assert values[key] == pytest.approx(PLANT[key], rel=0, abs=0), (node, controller, key)


def test_each_shared_constant_is_used_by_a_controller_under_the_plants_name():
    used = set()
    for node in CONTROLLER_NODES:
        used |= set(core_values(node_values(node)))
    missing = [k for k in SHARED if k not in used or k not in PLANT]
    assert not missing, f"constants not under one name: {missing}"


def test_derived_controller_constants_follow_the_plant():
    mpc = load_mpc_config("improved")
    alloc = load_allocator_config("improved")
    pid = load_pid_config()
    # the MPC's linear tyres: the plant's per-tyre cornering stiffness at static load
    c_f, c_r = PARAMS.static_cornering_stiffness()
    assert mpc.cornering_stiffness_front_static_n_per_rad == pytest.approx(c_f, rel=5e-3)
    assert mpc.cornering_stiffness_rear_static_n_per_rad == pytest.approx(c_r, rel=5e-3)
    # the relaxation-aware prediction's σ: the plant's MF 5.2 σ_α0 at static load
    fz = PARAMS.static_wheel_loads_n
    sig_f, sig_r = PARAMS.relaxation_length_m(fz[[0, 2]])
    assert mpc.relaxation_length_front_m == pytest.approx(sig_f, rel=5e-3)
    assert mpc.relaxation_length_rear_m == pytest.approx(sig_r, rel=5e-3)
    # the paper's allocation assumes B_f = B_r = B
    assert alloc.track_width_m == PLANT["track_width_front_m"] == PLANT["track_width_rear_m"]
    # the PID's torque range is the four motors together
    assert pid.max_total_torque_nm == 4 * PLANT["motor_torque_max_nm"]
    assert pid.min_total_torque_nm == -4 * PLANT["motor_torque_max_nm"]
    # the MPC's increment limits are the actuators' rate limits over one period
    for end in ("front", "rear"):
        rate = PLANT[f"max_steer_rate_{end}_deg_s"]
        assert getattr(mpc, f"max_dsteer_{end}_deg") == pytest.approx(rate * mpc.dt_s)


@pytest.mark.parametrize("node", CONTROLLER_NODES)
def test_the_package_params_files_set_none_of_the_cars_keys(node):
    from fourws_bringup.core.configs import package_file
    from fourws_common.params import load_ros_params_yaml
    from fourws_common.vehicle_info import load_vehicle_info, node_vehicle_values

    own = set(load_ros_params_yaml(str(package_file(node)), node))
    car = set(node_vehicle_values(node, load_vehicle_info()))
    assert car and not own & car, sorted(own & car)


@pytest.mark.parametrize("car", list_vehicles())
def test_every_shipped_car_loads_and_every_controller_takes_its_values(car):
    """The plant checks the car's recorded values against its own inputs; each controller's
    constants are the car's (the mean track where B_f and B_r differ; four motors)."""
    info = load_vehicle_info(car)
    plant = load_vehicle_params(car)
    assert plant.understeer_gradient() > 0.0          # a road car understeers
    mpc = load_mpc_config("improved", {"vehicle_file": car})
    pid = load_pid_config({"vehicle_file": car})
    alloc = load_allocator_config("improved", {"vehicle_file": car})
    assert (mpc.mass_kg, mpc.yaw_inertia_kg_m2, pid.mass_kg, alloc.mass_kg) == (
        plant.mass_kg, plant.yaw_inertia_kg_m2, plant.mass_kg, plant.mass_kg)
    assert (mpc.cg_to_front_axle_m, mpc.cg_to_rear_axle_m) == (
        plant.cg_to_front_axle_m, plant.cg_to_rear_axle_m)
    rec = plant.recorded_values()
    assert mpc.cornering_stiffness_front_static_n_per_rad == pytest.approx(
        rec["cornering_stiffness_front_static_n_per_rad"], rel=5e-3)
    assert mpc.relaxation_length_rear_m == pytest.approx(
        rec["relaxation_length_rear_static_m"], rel=5e-3)
    track = 0.5 * (plant.track_width_front_m + plant.track_width_rear_m)
    assert mpc.track_width_m == alloc.track_width_m == pytest.approx(track)
    assert pid.max_total_torque_nm == 4 * plant.motor_torque_max_nm == -pid.min_total_torque_nm
    assert pid.wheel_radius_m == alloc.wheel_radius_m == info.wheel_radius_m


def test_a_second_car_changes_only_the_cars_keys():
    paper = load_mpc_config("improved")
    other = load_mpc_config("improved", {"vehicle_file": "c_segment"})
    changed = {f.name for f in dataclasses.fields(paper)
               if getattr(paper, f.name) != getattr(other, f.name)}
    car_keys = set(node_vehicle_values("mpc_node", load_vehicle_info("c_segment")))
    assert changed and changed <= car_keys


def test_a_mismatch_override_wins_over_the_car():
    cfg = load_mpc_config("improved", {"vehicle_file": "c_segment", "mass_kg": 1500.0})
    assert cfg.mass_kg == 1500.0
    assert cfg.yaw_inertia_kg_m2 == load_vehicle_info("c_segment").yaw_inertia_kg_m2


@pytest.mark.parametrize(("edit", "needle", "controllers_see_it"), [
    ({"mass_kg": None}, "mass_kg", True),                        # a key left out
    ({"tyre_relaxation_load_factor": None}, "tyre_relaxation_load_factor", False),  # plant's
    ({"mass_kg": "heavy"}, "mass_kg", True),                     # a wrong type
    ({"max_steer_rear_deg": 90.0}, "max_steer_rear_deg", True),  # out of range
    # stale: a recorded value its own inputs contradict; only the plant has the tyre model
    ({"relaxation_length_front_static_m": 0.5}, "relaxation_length_front_static_m", False),
])
def test_a_bad_car_file_is_an_error_naming_the_key(tmp_path, edit, needle, controllers_see_it):
    raw = read_vehicle_file()
    for k, v in edit.items():
        if v is None:
            raw.pop(k)
        else:
            raw[k] = v
    path = tmp_path / "car.yaml"
    path.write_text(yaml.safe_dump(raw), encoding="utf-8")
    if controllers_see_it:
        with pytest.raises(ValueError, match=needle):
            load_vehicle_info(path)          # the controllers' part of the car
    with pytest.raises(ValueError, match=needle):
        load_vehicle_params(path)            # the plant's: every key, none defaulted


def test_an_unknown_car_name_lists_the_known_ones():
    with pytest.raises(ValueError, match="c_segment.*paper|paper.*c_segment"):
        load_vehicle_info("no_such_car")


def test_a_mismatch_study_is_an_explicit_override():
    nominal = load_mpc_config("improved")
    heavy = load_mpc_config("improved", {"mass_kg": 1.2 * PLANT["mass_kg"]})
    changed = [f.name for f in dataclasses.fields(nominal)
               if getattr(nominal, f.name) != getattr(heavy, f.name)]
    assert changed == ["mass_kg"]


def test_one_control_period_for_plant_and_controllers():
    from fourws_bringup.core.configs import plant_values
    from fourws_bringup.scoring import DEADLINE_MS

    dt = plant_values()["dt_s"]
    assert load_mpc_config("improved").dt_s == dt
    assert DEADLINE_MS == pytest.approx(dt * 1e3)


def test_the_plant_and_the_controllers_accept_the_same_range_of_every_shared_key():
    """A car file that the controllers' VehicleInfo accepts, the plant accepts too: the
    ranges of the keys both read have one owner (``vehicle_info.field_range``)."""
    plant = {f.name: f.metadata for f in dataclasses.fields(VehicleParams)}
    shared = [f.name for f in dataclasses.fields(VehicleInfo) if f.name in plant]
    assert len(shared) >= 15
    for name in shared:
        assert {k: plant[name][k] for k in ("lo", "hi", "unit")} == field_range(name), name


@pytest.mark.parametrize("config", [MpcConfig, AllocatorConfig, SpeedPidConfig])
def test_the_controllers_take_the_cars_range_of_every_car_key(config):
    """A controller's value of a car key (``track_width_m``: B = mean of B_f, B_r) accepts
    the range the car file does, from the one owner (``vehicle_info.field_range``)."""
    keys = {f.name for f in dataclasses.fields(VehicleInfo)}
    shared = [f for f in dataclasses.fields(config) if f.name in keys | {"track_width_m"}]
    assert len(shared) >= 2
    for f in shared:
        key = "track_width_front_m" if f.name == "track_width_m" else f.name
        assert {k: f.metadata[k] for k in ("lo", "hi", "unit")} == field_range(key), f.name
