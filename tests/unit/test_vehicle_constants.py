"""One name and one nominal value per vehicle constant: the controllers' params files agree
with the plant's ``vehicle.yaml``, so a model mismatch is always an explicit override."""

import dataclasses

import pytest

from fourws_bringup.core.configs import (
    core_values,
    list_controllers,
    load_allocator_config,
    load_mpc_config,
    load_pid_config,
    node_values,
)
from fourws_sim.core.vehicle_params import load_vehicle_params, read_vehicle_yaml

PLANT = read_vehicle_yaml()
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
