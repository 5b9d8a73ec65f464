"""In-wheel motor (eq. 32) and steering actuators, through the simulator's own integration."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from fourws_sim.core.actuators import (
    motor_derivative,
    motor_state_space,
    motor_transfer_function,
    steer_derivative,
)
from fourws_sim.core.plant_io import InitialState
from fourws_sim.core.road import ConstantRoad
from fourws_sim.core.simulator import Simulator
from fourws_sim.core.vehicle_params import load_vehicle_params

P = load_vehicle_params()


def _torque_step(step_nm: float, t_end: float = 0.4):
    sim = Simulator(P, ConstantRoad(1.0), InitialState(speed=10.0))
    t, torque = [0.0], [sim.outputs().wheel_torque.copy()]
    for _ in range(round(t_end / 0.001)):
        out = sim.step(0.0, 0.0, np.full(4, step_nm), dt_s=0.001)
        t.append(out.t_s)
        torque.append(out.wheel_torque.copy())
    return np.array(t), np.array(torque)


def test_motor_step_matches_eq32_transfer_function():
    tau = P.motor_time_constant_s
    t, torque = _torque_step(100.0)
    _, ref = signal.step(signal.TransferFunction(*motor_transfer_function(tau)), T=t)
    for i in range(4):
        np.testing.assert_allclose(torque[:, i], 100.0 * ref, atol=1e-3)


def test_motor_overshoot_is_that_of_damping_one_over_root_two():
    t, torque = _torque_step(100.0)
    overshoot = (torque[:, 0].max() - 100.0) / 100.0
    assert overshoot == pytest.approx(math.exp(-math.pi), abs=0.005)  # 4.32 %
    tau = P.motor_time_constant_s
    a, *_ = motor_state_space(tau)
    wn = math.sqrt(-a[1, 0])
    zeta = -a[1, 1] / (2 * wn)
    assert zeta == pytest.approx(1 / math.sqrt(2), rel=1e-12)
    assert wn == pytest.approx(1 / (math.sqrt(2) * tau), rel=1e-12)


def test_state_space_and_derivative_agree():
    a, b, c, d = motor_state_space(0.02)
    x = np.array([12.0, -300.0])
    xd = a @ x + b[:, 0] * 50.0
    assert motor_derivative(12.0, -300.0, 50.0, 0.02) == pytest.approx(tuple(xd))
    w = np.array([0.1, 10.0, 35.0, 300.0])
    h_ss = [(c @ np.linalg.solve(1j * wk * np.eye(2) - a, b) + d)[0, 0] for wk in w]
    _, h_tf = signal.freqresp(signal.TransferFunction(*motor_transfer_function(0.02)), w)
    np.testing.assert_allclose(h_ss, h_tf, rtol=1e-9)


def test_torque_command_is_clipped_to_the_motor_limit():
    sim = Simulator(P, ConstantRoad(1.0), InitialState(speed=10.0))
    for _ in range(50):
        out = sim.step(0.0, 0.0, np.array([2000.0, -2000.0, 100.0, 0.0]))
    assert sim.last_clipped == ("wheel_torque[0]", "wheel_torque[1]")
    np.testing.assert_allclose(out.wheel_torque[:2], [500.0, -500.0], rtol=1e-3)


def test_steering_is_a_rate_limited_first_order_lag():
    lim = P.actuator_limits()
    sim = Simulator(P, ConstantRoad(1.0), InitialState(speed=10.0))
    cmd_f, cmd_r = math.radians(10.0), math.radians(5.0)
    t, df, dr = [], [], []
    for _ in range(100):
        out = sim.step(cmd_f, cmd_r, np.zeros(4))
        t.append(out.t_s)
        df.append(out.steer_front)
        dr.append(out.steer_rear)
    t, df, dr = map(np.array, (t, df, dr))
    # rate-limited phase: straight ramps at the limits
    assert df[9] == pytest.approx(lim.max_steer_rate_front_rad_s * t[9], rel=1e-9)
    assert dr[4] == pytest.approx(lim.max_steer_rate_rear_rad_s * t[4], rel=1e-9)
    assert np.max(np.diff(df)) <= lim.max_steer_rate_front_rad_s * 0.01 * (1 + 1e-9)
    # lag phase: the rate limit ends at δ = cmd − τ·rate_max, then exponential
    tau = P.steer_front_time_constant_s
    t_end_ramp = (cmd_f - tau * lim.max_steer_rate_front_rad_s) / lim.max_steer_rate_front_rad_s
    k = np.searchsorted(t, t_end_ramp + 0.2)
    expected = cmd_f - tau * lim.max_steer_rate_front_rad_s * np.exp(-(t[k] - t_end_ramp) / tau)
    assert df[k] == pytest.approx(expected, rel=1e-4)
    assert df[-1] == pytest.approx(cmd_f, rel=1e-6)
    assert steer_derivative(0.0, 1.0, 0.05, 0.5) == 0.5
    assert steer_derivative(0.0, 0.01, 0.05, 0.5) == pytest.approx(0.2)


def test_steer_command_beyond_the_angle_limit_is_clipped():
    sim = Simulator(P, ConstantRoad(1.0), InitialState(speed=10.0))
    for _ in range(300):
        out = sim.step(math.radians(45.0), -math.radians(20.0), np.zeros(4))
    assert sim.last_clipped == ("steer_front", "steer_rear")
    assert out.steer_front == pytest.approx(math.radians(P.max_steer_front_deg), rel=1e-6)
    assert out.steer_rear == pytest.approx(-math.radians(P.max_steer_rear_deg), rel=1e-6)


@pytest.mark.parametrize(
    "args",
    [(math.nan, 0.0, np.zeros(4)), (0.0, math.inf, np.zeros(4)),
     (0.0, 0.0, np.array([0.0, math.nan, 0.0, 0.0])), (0.0, 0.0, np.zeros(3))],
)
def test_non_finite_or_malformed_commands_raise(args):
    sim = Simulator(P, ConstantRoad(1.0), InitialState(speed=10.0))
    before = sim.state()
    with pytest.raises(ValueError):
        sim.step(*args)
    np.testing.assert_array_equal(sim.state(), before)
    assert sim.t_s == 0.0


def test_dt_must_be_a_multiple_of_the_substep():
    sim = Simulator(P, ConstantRoad(1.0), InitialState(speed=10.0))
    with pytest.raises(ValueError, match="dt_s"):
        sim.step(0.0, 0.0, np.zeros(4), dt_s=0.0105)
    out = sim.step(0.0, 0.0, np.zeros(4), dt_s=0.02)
    assert out.t_s == 0.02
