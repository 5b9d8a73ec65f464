"""Simulator API: outputs match the VehicleState message, state layout, time grid."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest

from fourws_sim.core.plant_io import InitialState, PlantOutputs
from fourws_sim.core.road import ConstantRoad
from fourws_sim.core.simulator import Simulator
from fourws_sim.core.vehicle import N_STATE, State, TwoTrackModel
from fourws_sim.core.vehicle_params import load_vehicle_params

ROOT = Path(__file__).resolve().parents[2]
P = load_vehicle_params()


def test_outputs_carry_every_vehicle_state_message_field():
    text = (ROOT / "src" / "fourws_msgs" / "msg" / "VehicleState.msg").read_text(
        encoding="utf-8")
    fields = set()
    for line in text.splitlines():
        m = re.match(r"\s*(float64(?:\[4\])?)\s+(\w+)", line)
        if m:
            fields.add(m.group(2))
    ours = {f.name for f in dataclasses.fields(PlantOutputs)}
    assert fields == ours - {"t_s"}
    out = Simulator(P, ConstantRoad(1.0), InitialState(speed=5.0)).outputs()
    for name in ("wheel_speed", "wheel_torque", "fx", "fy", "fz", "mu"):
        assert getattr(out, name).shape == (4,)


def test_derivative_rows_follow_the_state_enum():
    rng = np.random.default_rng(3)
    y = list(rng.uniform(-1.0, 1.0, N_STATE))
    y[State.VX] = 12.0
    y[State.YAW] = 0.7
    model = TwoTrackModel(P)
    u = (0.05, -0.02, 10.0, 20.0, 30.0, 40.0)
    d = model.derivatives(y, u, (1.0, 1.0, 1.0, 1.0))
    vx, vy, yaw = y[State.VX], y[State.VY], y[State.YAW]
    assert d[State.X] == pytest.approx(vx * math.cos(yaw) - vy * math.sin(yaw))
    assert d[State.Y] == pytest.approx(vx * math.sin(yaw) + vy * math.cos(yaw))
    assert d[State.YAW] == y[State.R]
    tau = P.motor_time_constant_s
    for i, (t, rate) in enumerate(((State.TORQUE_FL, State.TORQUE_RATE_FL),
                                   (State.TORQUE_FR, State.TORQUE_RATE_FR),
                                   (State.TORQUE_RL, State.TORQUE_RATE_RL),
                                   (State.TORQUE_RR, State.TORQUE_RATE_RR))):
        assert d[t] == y[rate]
        assert d[rate] == pytest.approx((u[2 + i] - y[t] - 2 * tau * y[rate]) / (2 * tau * tau))
    lim = P.actuator_limits()
    assert d[State.STEER_FRONT] == pytest.approx(
        float(np.clip((0.05 - y[State.STEER_FRONT]) / P.steer_front_time_constant_s,
                      -lim.max_steer_rate_front_rad_s, lim.max_steer_rate_front_rad_s)))
    info: dict = {}
    model.derivatives(y, u, (1.0, 1.0, 1.0, 1.0), info)
    assert d[State.VX] == pytest.approx(info["ax"] + vy * y[State.R])
    assert d[State.VY] == pytest.approx(info["ay"] - vx * y[State.R])
    assert d[State.AX_FILTERED] == pytest.approx(
        (info["ax"] - y[State.AX_FILTERED]) / P.load_transfer_time_constant_s)
    # transient slip: dα'/dt = (α − α') max(|v_x,i|, v_min) / σ(F_z), wheel-frame v_x,i
    sigma = P.relaxation_length_m(np.array(info["fz"]))
    xw, yw = P.wheel_positions_m()
    r = y[State.R]
    for i, steer in enumerate((State.STEER_FRONT,) * 2 + (State.STEER_REAR,) * 2):
        vxi = (vx - yw[i] * r) * math.cos(y[steer]) + (vy + xw[i] * r) * math.sin(y[steer])
        den = max(abs(vxi), P.slip_speed_min_mps)
        assert d[State.ALPHA_FL + i] == pytest.approx(
            (info["alpha"][i] - y[State.ALPHA_FL + i]) * den / sigma[i])


def test_time_is_on_the_step_grid_and_clipping_is_reported():
    sim = Simulator(P, ConstantRoad(1.0), InitialState(speed=10.0))
    for k in range(1, 301):
        out = sim.step(0.01, 0.0, np.full(4, 20.0))
        assert out.t_s == round(k * 0.01, 12)
    assert sim.t_s == 3.0 and sim.last_clipped == ()


def test_bad_substep_raises():
    with pytest.raises(ValueError, match="substep_s"):
        Simulator(P, ConstantRoad(1.0), InitialState(), substep_s=0.0)
    with pytest.raises(ValueError, match="initial.speed"):
        InitialState(speed=math.nan)
