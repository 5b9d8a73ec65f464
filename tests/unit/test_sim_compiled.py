"""The compiled plant (model_jit.py, rk4.py) against its plain-Python reference.

``TwoTrackModel.derivatives`` and ``tyre.forces_scalar`` are the readable statement of the
model; the compiled twin must give the same numbers (same operations in the same order: in
practice bit for bit, allowed here a relative 1e-12), and ``Simulator`` must give the same
trajectories as its plain-Python RK4 loop (``jit=False``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fourws_sim.core import model_jit, rk4
from fourws_sim.core.plant_io import InitialState
from fourws_sim.core.road import ConstantRoad, PiecewiseXRoad, SplitRoad
from fourws_sim.core.simulator import Simulator
from fourws_sim.core.tyre import forces_scalar
from fourws_sim.core.vehicle import N_STATE, State, TwoTrackModel
from fourws_sim.core.vehicle_params import load_vehicle_params

P = load_vehicle_params()
P_NO_RELAX = dataclasses.replace(P, tyre_relaxation_peak_over_radius=0.0)
RTOL = 1e-12


def _random_state(rng: np.random.Generator) -> np.ndarray:
    """A state anywhere in the envelope: forward and reverse, sliding, wheel lift."""
    y = np.zeros(N_STATE)
    y[State.VX] = rng.choice([rng.uniform(-30.0, 40.0), rng.uniform(-3.0, 3.0)])
    y[State.VY] = rng.normal(0.0, 2.0)
    y[State.R] = rng.normal(0.0, 0.8)
    y[State.X:State.YAW + 1] = rng.normal(0.0, 50.0, 3)
    slip = rng.choice([0.0, 0.02, 0.3]) * rng.normal(size=4)
    y[State.OMEGA_FL:State.OMEGA_RR + 1] = y[State.VX] * (1.0 + slip) / P.wheel_radius_m
    y[State.TORQUE_FL:State.TORQUE_RR + 1] = rng.normal(0.0, 300.0, 4)
    y[State.TORQUE_RATE_FL:State.TORQUE_RATE_RR + 1] = rng.normal(0.0, 2000.0, 4)
    y[State.STEER_FRONT] = rng.normal(0.0, 0.1)
    y[State.STEER_REAR] = rng.normal(0.0, 0.05)
    # lagged accelerations up to ±15 m/s²: beyond ≈ ±8 the inner wheels lift (F_z = 0)
    y[State.AX_FILTERED:State.AY_FILTERED + 1] = rng.uniform(-15.0, 15.0, 2)
    y[State.ALPHA_FL:State.ALPHA_RR + 1] = rng.normal(0.0, 0.1, 4)
    return y


@pytest.mark.parametrize("params", [P, P_NO_RELAX], ids=["relaxation", "no_relaxation"])
def test_compiled_derivatives_equal_the_reference(params):
    model = TwoTrackModel(params)
    c = model_jit.model_constants(model)
    rng = np.random.default_rng(11)
    dy, wt = np.empty(N_STATE), model_jit.wheel_table()
    lifted = reverse = 0
    for _ in range(2000):
        y = _random_state(rng)
        u = np.concatenate([rng.normal(0.0, 0.2, 2), rng.normal(0.0, 400.0, 4)])
        mu = rng.uniform(0.05, 1.5, 4)
        info: dict = {}
        ref = model.derivatives(y.tolist(), tuple(u), tuple(mu), info)
        ax, ay = model_jit.derivatives(y, u, mu, c, dy, wt)
        np.testing.assert_allclose(dy, ref, rtol=RTOL, atol=0.0)
        np.testing.assert_allclose((ax, ay), (info["ax"], info["ay"]), rtol=RTOL, atol=0.0)
        for row, key in ((model_jit.FX, "fx"), (model_jit.FY, "fy"), (model_jit.FZ, "fz"),
                         (model_jit.ALPHA, "alpha")):
            np.testing.assert_allclose(wt[row], info[key], rtol=RTOL, atol=0.0)
        aux = rk4.outputs(y, u, mu, c)
        np.testing.assert_allclose(
            aux, (info["ax"], info["ay"], *info["fx"], *info["fy"], *info["fz"],
                  *info["alpha"]), rtol=RTOL, atol=0.0)
        lifted += min(info["fz"]) == 0.0
        reverse += y[State.VX] < -3.0
    assert lifted > 100 and reverse > 100  # the envelope's corners were visited
    if params.tyre_relaxation_peak_over_radius == 0.0:
        assert not dy[State.ALPHA_FL:].any()


def test_compiled_tyre_equals_forces_scalar():
    rng = np.random.default_rng(5)
    model = TwoTrackModel(P)
    c = model_jit.model_constants(model)
    k_front = P.tyre("front").scalar_constants(P.tyre_cornering_coeff_front)
    k_rear = P.tyre("rear").scalar_constants(P.tyre_cornering_coeff_rear)
    wt = model_jit.wheel_table()
    for _ in range(3000):
        kappa = rng.choice([0.0, 0.01, 0.3, 3.0]) * rng.normal(size=4)
        alpha = rng.choice([0.0, 0.02, 0.5]) * rng.normal(size=4)
        fz = rng.choice([0.0, 1.0]) * rng.uniform(0.0, 9000.0, 4)
        mu = rng.uniform(0.05, 1.5, 4)
        wt[model_jit.KAPPA], wt[model_jit.SLIP], wt[model_jit.FZ] = kappa, alpha, fz
        model_jit.tyre_forces(wt, mu, c)
        for i, k in enumerate((k_front, k_front, k_rear, k_rear)):
            fx, fy = forces_scalar(kappa[i], alpha[i], fz[i], mu[i], k)
            np.testing.assert_allclose((wt[model_jit.FX, i], wt[model_jit.FY, i]), (fx, fy),
                                       rtol=RTOL, atol=0.0)


def test_constants_are_the_models():
    model = TwoTrackModel(P)
    c = model_jit.model_constants(model)
    assert c.shape == (model_jit.N_CONSTANTS,)
    assert tuple(c[:len(model.constants())]) == model.constants()
    xw, yw = P.wheel_positions_m()
    np.testing.assert_array_equal(c[model_jit.WHEEL_X:model_jit.WHEEL_X + 4], xw)
    np.testing.assert_array_equal(c[model_jit.WHEEL_Y:model_jit.WHEEL_Y + 4], yw)


def _commands(k: int) -> tuple[float, float, np.ndarray]:
    """Steer and torque commands varying every step, with clipping now and then."""
    t = 0.01 * k
    d = math.radians(4.0) * math.sin(2.0 * math.pi * t / 1.7) + (0.8 if k % 97 == 0 else 0.0)
    torque = np.array([120.0, 150.0, 90.0, 60.0]) * math.sin(2.0 * math.pi * t / 2.3)
    if k % 53 == 0:
        torque[1] = 1e4
    return d, -0.4 * d, torque


CASES = {
    "uniform": dict(road=ConstantRoad(0.6)),
    "split": dict(road=SplitRoad(0.9, 0.3)),
    "mu_steps": dict(road=PiecewiseXRoad([20.0, 35.0, 50.0], [1.0, 0.3, 0.8, 0.5])),
    "dead_time": dict(road=ConstantRoad(0.8), steer_dead_time_s=0.015),
    "dead_time_mu_steps": dict(road=PiecewiseXRoad([25.0], [0.9, 0.4]),
                               steer_dead_time_s=0.03),
    "no_relaxation": dict(road=ConstantRoad(0.7), vehicle=P_NO_RELAX),
    "substep_2ms": dict(road=ConstantRoad(0.7), substep_s=0.002),
}


@pytest.mark.parametrize("case", list(CASES))
def test_simulator_matches_the_plain_python_loop(case):
    kw = dict(CASES[case])
    vehicle = kw.pop("vehicle", P)
    road = kw.pop("road")
    initial = InitialState(x=1.0, y=-0.5, yaw=0.05, speed=16.0)
    sims = [Simulator(vehicle, road, initial, jit=jit, **kw) for jit in (True, False)]
    np.testing.assert_allclose(sims[0].state(), sims[1].state(), rtol=0.0, atol=1e-12)
    clipped, mus = set(), set()
    for k in range(300):
        cmd = _commands(k)
        dt = 0.02 if k % 41 == 0 else 0.01
        fast, ref = (sim.step(*cmd, dt_s=dt) for sim in sims)
        assert sims[0].last_clipped == sims[1].last_clipped
        clipped.update(sims[0].last_clipped)
        mus.update(fast.mu)
        assert fast.t_s == ref.t_s == sims[1].t_s
        for name, value in dataclasses.asdict(ref).items():
            np.testing.assert_allclose(getattr(fast, name), value, rtol=1e-9, atol=1e-9,
                                       err_msg=f"{case}: {name} at step {k}")
        np.testing.assert_allclose(sims[0].state(), sims[1].state(), rtol=1e-9, atol=1e-9)
    # the run went through what it should test: clipping, every μ of the road, distance
    assert {"steer_front", "wheel_torque[1]"} <= clipped
    assert len(mus) == {"split": 2, "mu_steps": 4, "dead_time_mu_steps": 2}.get(case, 1)
    assert sims[0].outputs().x > 40.0


def test_state_is_a_copy_and_bad_commands_raise():
    sim = Simulator(P, ConstantRoad(1.0), InitialState(speed=10.0))
    s = sim.state()
    s[:] = 0.0
    assert sim.state()[State.VX] == 10.0
    with pytest.raises(ValueError, match="steer_front_cmd"):
        sim.step(math.nan, 0.0, np.zeros(4))
    with pytest.raises(ValueError, match="wheel_torque_cmd"):
        sim.step(0.0, 0.0, np.array([0.0, math.inf, 0.0, 0.0]))
    with pytest.raises(ValueError, match="dt_s"):
        sim.step(0.0, 0.0, np.zeros(4), dt_s=0.0105)
    assert sim.t_s == 0.0 and sim.state()[State.VX] == 10.0
