"""Road μ: constant, piecewise along X, split by wheel side; per-wheel μ in the plant."""

from __future__ import annotations

import numpy as np
import pytest

from fourws_common.wheels import WHEEL_SIDE, Wheel
from fourws_sim.core.plant_io import InitialState
from fourws_sim.core.road import (
    ConstantRoad,
    PiecewiseXRoad,
    SplitRoad,
    road_from_mapping,
)
from fourws_sim.core.simulator import Simulator
from fourws_sim.core.vehicle_params import load_vehicle_params

SIDE = np.array(WHEEL_SIDE)
P = load_vehicle_params()


def test_constant_road():
    r = road_from_mapping({"type": "constant", "mu": 0.5})
    np.testing.assert_array_equal(r.mu_at(np.arange(4.0), np.zeros(4), SIDE), [0.5] * 4)
    assert r.mu4((0.0,) * 4, (0.0,) * 4) == (0.5,) * 4 and r.mu_min() == 0.5


def test_piecewise_road_steps_at_the_given_x_and_both_apis_agree():
    r = road_from_mapping({"type": "piecewise_x", "x_m": [10.0, 20.0], "mu": [0.9, 0.4, 0.7]})
    x = np.array([9.999, 10.0, 19.9, 25.0])
    np.testing.assert_array_equal(r.mu_at(x, np.zeros(4), SIDE), [0.9, 0.4, 0.4, 0.7])
    assert r.mu4(tuple(x), (0.0,) * 4) == (0.9, 0.4, 0.4, 0.7)
    assert r.mu_min() == 0.4


def test_split_road_by_wheel_side():
    r = road_from_mapping({"type": "split", "mu_left": 0.8, "mu_right": 0.3})
    np.testing.assert_array_equal(r.mu_at(np.zeros(4), np.zeros(4), SIDE), [0.8, 0.3, 0.8, 0.3])
    assert r.mu4((0.0,) * 4, (0.0,) * 4) == (0.8, 0.3, 0.8, 0.3)


@pytest.mark.parametrize(
    "mapping, key",
    [({"type": "constant", "mu": 0.0}, "mu"), ({"type": "constant", "mu": True}, "mu"),
     ({"type": "ice"}, "road.type"), ({"type": "constant", "mu": 0.5, "x": 1}, "unknown"),
     ({"type": "piecewise_x", "x_m": [1.0], "mu": [0.5]}, "len"),
     ({"type": "piecewise_x", "x_m": [2.0, 1.0], "mu": [0.5, 0.6, 0.7]}, "increasing"),
     ({"type": "split", "mu_left": 0.5}, "mu_right")],
)
def test_bad_roads_raise_naming_the_problem(mapping, key):
    with pytest.raises(ValueError, match=key):
        road_from_mapping(mapping)


def test_front_wheels_meet_a_mu_step_before_the_rear_wheels():
    road = PiecewiseXRoad([20.0], [0.9, 0.45])
    sim = Simulator(P, road, InitialState(x=0.0, speed=10.0))
    seen = []
    for _ in range(400):
        out = sim.step(0.0, 0.0, np.full(4, 30.0))
        seen.append(out.mu.copy())
        if out.x > 25.0:
            break
    seen = np.array(seen)
    mixed = (seen[:, Wheel.FL] == 0.45) & (seen[:, Wheel.RL] == 0.9)
    assert mixed.any()  # the wheelbase: the front axle is on the new surface first
    assert np.all(seen[-1] == 0.45)


def test_split_mu_braking_yaws_the_car_towards_the_high_mu_side():
    sim = Simulator(P, SplitRoad(0.8, 0.3), InitialState(speed=20.0))
    for _ in range(100):
        out = sim.step(0.0, 0.0, np.full(4, -300.0))
    assert out.yaw_rate > 0.0  # more braking force on the left: the car turns left
    assert out.fx[Wheel.FL] < out.fx[Wheel.FR] < 0.0


def test_constant_road_is_cheap_path():
    assert ConstantRoad(1.0).uniform and SplitRoad(0.5, 0.6).uniform
    assert not PiecewiseXRoad([0.0], [0.5, 0.6]).uniform
