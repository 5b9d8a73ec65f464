"""The adapter's conversion from standard messages (core.standard_inputs) and its YAML."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fourws_bringup.core.standard_inputs import JointMap, controller_input, yaw_of
from fourws_common.params import check_field, from_mapping, load_ros_params_yaml
from fourws_common.resources import config_dir
from fourws_common.vehicle_info import read_vehicle_file
from fourws_common.wheels import JOINT_NAMES
from fourws_torque_alloc.core.tyre_estimate import EstimatorParams, TyreEstimator


@pytest.mark.parametrize("yaw", [0.0, 0.3, -1.2, 3.0, -3.1])
def test_yaw_of_a_quaternion_about_z(yaw):
    assert yaw_of(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)) == pytest.approx(yaw, abs=1e-12)


def test_yaw_of_a_tilted_quaternion_is_the_zyx_yaw():
    # yaw 0.5 then pitch 0.2 (z-y-x): the heading is still 0.5
    cy, sy, cp, sp = math.cos(0.25), math.sin(0.25), math.cos(0.1), math.sin(0.1)
    q = (-sy * sp, cy * sp, sy * cp, cy * cp)
    assert yaw_of(*q) == pytest.approx(0.5, abs=1e-12)
    with pytest.raises(ValueError, match="unit quaternion"):
        yaw_of(0.0, 0.0, 0.0, 0.0)


def test_joints_by_name_in_any_order_and_missing_ones_named():
    jm = JointMap(("steer_fl", "steer_fr"), ("steer_rear",), ("a", "b", "c", "d"))
    names = ["d", "steer_fr", "c", "steer_rear", "b", "steer_fl", "a"]
    pos = [0.0, 0.12, 0.0, -0.03, 0.0, 0.10, 0.0]
    vel = [4.0, 0.0, 3.0, 0.0, 2.0, 0.0, 1.0]
    f, r, w = jm.read(names, pos, vel)
    assert f == pytest.approx(0.11) and r == pytest.approx(-0.03)
    assert w.tolist() == [1.0, 2.0, 3.0, 4.0]
    with pytest.raises(ValueError, match="steer_fl"):
        jm.read(names[1:], pos[1:], vel[1:])
    with pytest.raises(ValueError, match="velocity"):
        jm.read(names, pos, vel[:3])
    with pytest.raises(ValueError, match="4 names"):
        JointMap(wheels=("a", "b"))


def test_controller_input_takes_what_is_measured_and_estimates_the_tyres():
    est = TyreEstimator(EstimatorParams.from_mapping({**read_vehicle_file(),
                                                      "mu_nominal": 0.7}))
    yaw = 0.2
    s = controller_input((10.0, -2.0, 0.0, 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)),
                         (16.0, 0.3, 0.25), (0.2, 0.5, 3.0),
                         (list(JOINT_NAMES), [0.05, -0.01, 0, 0, 0, 0], [0, 0, 59, 60, 61, 62]),
                         JointMap(), est)
    assert (s.x, s.y, s.vx, s.vy) == (10.0, -2.0, 16.0, 0.3)
    assert s.yaw == pytest.approx(yaw) and s.yaw_rate == 0.2      # from the IMU
    assert (s.ax, s.ay, s.steer_front, s.steer_rear) == (0.5, 3.0, 0.05, -0.01)
    assert s.sideslip == pytest.approx(math.atan2(0.3, 16.0))
    assert s.wheel_speed.tolist() == [59, 60, 61, 62]
    fz, fy, mu = est.estimate(0.5, 3.0)
    np.testing.assert_array_equal(s.fz, fz)
    np.testing.assert_array_equal(s.fy, fy)
    assert s.mu.tolist() == [0.7] * 4
    p = est.p
    assert s.fz.sum() == pytest.approx(p.mass_kg * p.gravity_mps2)   # loads carry the car
    assert s.fy.sum() == pytest.approx(p.mass_kg * 3.0)              # and its m a_y
    odom = controller_input((0, 0, 0, 0, 0, 0, 1), (1.0, 0.0, 0.4), (0.2, 0, 0),
                            (list(JOINT_NAMES), [0] * 6, [0] * 6), JointMap(), est,
                            yaw_rate_from="odom")
    assert odom.yaw_rate == 0.4
    with pytest.raises(ValueError, match="vx"):
        controller_input((0, 0, 0, 0, 0, 0, 1), (float("nan"), 0.0, 0.0), (0, 0, 0),
                         (list(JOINT_NAMES), [0] * 6, [0] * 6), JointMap(), est)


def test_adapter_yaml_mirrors_the_defaults_and_string_lists_are_checked():
    from fourws_bringup.adapter_node import AdapterConfig

    values = load_ros_params_yaml(str(config_dir("fourws_bringup") / "adapter.yaml"),
                                  "adapter_node")
    assert set(values) == {f.name for f in dataclasses.fields(AdapterConfig)}
    assert from_mapping(AdapterConfig, values) == AdapterConfig()
    assert check_field(AdapterConfig, "wheel_joints", ["a", "b", "c", "d"]) == ("a", "b", "c",
                                                                               "d")
    with pytest.raises(ValueError, match="wheel_joints"):
        check_field(AdapterConfig, "wheel_joints", [1.0, 2.0])
    with pytest.raises(ValueError, match="wheel_joints"):
        from_mapping(AdapterConfig, {**values, "wheel_joints": ["a", "b"]})


@pytest.mark.parametrize(("twist", "imu", "position", "velocity", "needle"), [
    ((16.0, 0.0, 0.0), (0.0, 1e308, 0.0), [0] * 6, [0] * 6, "ax"),     # made the loads inf
    ((1e300, 0.0, 0.0), (0.0, 0.0, 0.0), [0] * 6, [0] * 6, "vx"),
    ((16.0, 0.0, 0.0), (50.0, 0.0, 0.0), [0] * 6, [0] * 6, "yaw_rate"),
    ((16.0, 0.0, 0.0), (0.0, 0.0, 0.0), [4.0, 0, 0, 0, 0, 0], [0] * 6, "steer_front"),
    ((16.0, 0.0, 0.0), (0.0, 0.0, 0.0), [0] * 6, [0, 0, 1e9, 0, 0, 0], "wheel_speed"),
])
def test_a_finite_but_absurd_measurement_is_refused_naming_it(twist, imu, position, velocity,
                                                               needle):
    est = TyreEstimator(EstimatorParams.from_mapping({**read_vehicle_file(),
                                                      "mu_nominal": 0.7}))
    with pytest.raises(ValueError, match=f"implausible {needle}"):
        controller_input((0, 0, 0, 0, 0, 0, 1), twist, imu,
                         (list(JOINT_NAMES), position, velocity), JointMap(), est)
