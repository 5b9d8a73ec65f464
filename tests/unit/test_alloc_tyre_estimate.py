"""Tyre-force estimate without plant truth: loads sum to m g and equal the plant's steady
quasi-static transfer; lateral forces balance m a_y and the yaw moment; μ is the nominal."""

import numpy as np
import pytest

from fourws_common.vehicle_info import read_vehicle_file
from fourws_sim.core.scenario import load_scenario
from fourws_sim.core.simulator import Simulator
from fourws_torque_alloc.core.tyre_estimate import EstimatorParams, TyreEstimator

P = EstimatorParams.from_mapping({**read_vehicle_file(), "mu_nominal": 0.8})
EST = TyreEstimator(P)


@pytest.mark.parametrize("ax, ay", [(0.0, 0.0), (1.5, 0.0), (-3.0, 2.0), (0.5, -4.5)])
def test_loads_sum_to_the_weight_and_forces_balance(ax, ay):
    fz, fy, mu = EST.estimate(ax, ay)
    assert fz.sum() == pytest.approx(P.mass_kg * P.gravity_mps2, rel=1e-12)
    assert fy.sum() == pytest.approx(P.mass_kg * ay, abs=1e-9)
    a, b = P.cg_to_front_axle_m, P.cg_to_rear_axle_m
    assert a * (fy[0] + fy[1]) - b * (fy[2] + fy[3]) == pytest.approx(0.0, abs=1e-6)
    np.testing.assert_array_equal(mu, P.mu_nominal)


def test_loads_match_the_plants_in_steady_cornering():
    s = load_scenario("circle_mu10")
    sim = Simulator.from_scenario(s)
    out = sim.outputs()
    for _ in range(600):                     # 6 s at a constant steer and drive torque
        out = sim.step(0.03, 0.0, np.full(4, 40.0), 0.01)
    fz, _, _ = EST.estimate(out.ax, out.ay)
    assert abs(out.ay) > 2.0                 # a real turn
    np.testing.assert_allclose(fz, out.fz, rtol=0.01)


def test_a_wheel_in_the_air_has_no_load():
    fz = EST.fz(0.0, 30.0)
    assert fz.min() == 0.0 and fz.sum() > 0.0
