"""The relaxation-aware prediction model (``relaxation_model``): exact Jacobians, the limit
σ → 0, the slip observer against the lag it inverts and against the plant's tyres, and the
controller's handling of the observer's memory."""

import dataclasses
import math

import numpy as np
import pytest

from fourws_mpc.core import actuator_model
from fourws_mpc.core import relaxation_model as RM
from fourws_mpc.core.config import MpcConfig
from fourws_mpc.core.controller import MpcController, VehicleSample
from fourws_mpc.core.model import ModelParams, StateIdx
from fourws_mpc.core.prediction_model import make_prediction_model
from fourws_mpc.core.reference import Reference
from fourws_sim.core.plant_io import InitialState
from fourws_sim.core.road import ConstantRoad
from fourws_sim.core.simulator import Simulator
from fourws_sim.core.vehicle import State
from fourws_sim.core.vehicle_params import load_vehicle_params

P = ModelParams()
T = 0.01
V = 60 / 3.6
R_ = RM.RelaxIdx


def _point(rng, vx=V):
    z = np.array([rng.uniform(-0.5, 0.5), vx, rng.uniform(-0.2, 0.2), rng.uniform(-0.3, 0.3),
                  rng.uniform(-1, 1), rng.uniform(0, 50), rng.uniform(-0.1, 0.1),
                  rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05),
                  rng.uniform(-0.05, 0.05)])
    return z, np.array([rng.uniform(-0.1, 0.1), rng.uniform(-0.05, 0.05),
                        rng.uniform(-1000, 1000)])


@pytest.mark.parametrize("vx", [V, 25.0, 0.5])          # 0.5 m/s: below the speed floor
def test_jacobians_equal_central_finite_differences(vx):
    rng = np.random.default_rng(7)
    for _ in range(5):
        z, u = _point(rng, vx)
        f, A, B = RM.jacobians(z, u, P)
        np.testing.assert_allclose(f, RM.dynamics(z, u, P), rtol=1e-12)
        for j in range(RM.N_STATE_RELAX):
            h = 1e-6 * max(1.0, abs(z[j]))
            dz = np.zeros_like(z)
            dz[j] = h
            if vx < P.min_speed_mps and j == StateIdx.VX:
                h = min(h, (P.min_speed_mps - vx) / 4)          # stay below the floor
                dz[j] = h
            fd = (RM.dynamics(z + dz, u, P) - RM.dynamics(z - dz, u, P)) / (2 * h)
            np.testing.assert_allclose(A[:, j], fd, rtol=1e-6, atol=1e-6, err_msg=f"col {j}")
        for j in range(3):
            h = 1e-6 * max(1.0, abs(u[j]))
            du = np.zeros(3)
            du[j] = h
            fd = (RM.dynamics(z, u + du, P) - RM.dynamics(z, u - du, P)) / (2 * h)
            np.testing.assert_allclose(B[:, j], fd, rtol=1e-6, atol=1e-6)


def test_with_the_transient_slip_at_its_kinematic_value_it_is_the_actuator_model():
    """α' = α: the forces of eq. (1); the body rows equal the actuator model's, and α'
    does not move."""
    rng = np.random.default_rng(2)
    z, u = _point(rng)
    z[R_.ALPHA_F], z[R_.ALPHA_R] = RM.kinematic_slip(z, P)
    f = RM.dynamics(z, u, P)
    np.testing.assert_allclose(f[:actuator_model.N_STATE_ACT],
                               actuator_model.dynamics(z[:actuator_model.N_STATE_ACT], u, P),
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(f[[R_.ALPHA_F, R_.ALPHA_R]], 0.0, atol=1e-12)


def test_a_short_relaxation_length_predicts_what_the_actuator_model_predicts():
    """σ = 1 mm (a lag of 60 µs at 60 km/h): over 12 periods the zero-order-hold
    predictions of the two models agree to within 0.5 % of the motion."""
    short = dataclasses.replace(P, relaxation_length_front_m=1e-3,
                                relaxation_length_rear_m=1e-3)
    relax = make_prediction_model("single_track_relaxation", short, "zoh")
    act = make_prediction_model("single_track_actuators", short, "zoh")
    z6 = np.array([0.1, V, 0.02, 0.05, 0.3, 0.0])
    u = np.array([0.02, -0.01, 200.0])
    za, _ = act.measured_state(z6, 0.01, 0.0)
    zr, _ = relax.measured_state(z6, 0.01, 0.0)
    A1, B1, d1 = act.discretise(za, u, T)
    A2, B2, d2 = relax.discretise(zr, u, T)
    for _ in range(12):
        za = A1 @ za + B1 @ u + d1
        zr = A2 @ zr + B2 @ u + d2
    moved = np.abs(za[:6] - z6)
    assert np.all(np.abs(zr[:6] - za[:6]) <= 0.005 * moved + 1e-9), (zr[:6] - za[:6], moved)


def test_the_observer_is_exact_for_a_slip_ramp_between_samples():
    """The first-order hold: α varying linearly between samples drives the lag
    τ dα'/dt = α − α' exactly (closed form of the ramp response)."""
    obs = RM.SlipObserver(P)
    tau = P.relaxation_length_front_m / V
    slope = 0.3                                        # rad/s
    z = np.zeros(actuator_model.N_STATE_ACT)
    z[StateIdx.VX] = V
    _, mem = obs.estimate(z, None, T)                  # α = α' = 0 at t = 0
    for k in range(1, 30):
        t = k * T
        z[actuator_model.ActIdx.DF_ACT] = slope * t    # α_f = δ_f at v_y = r = 0
        est, mem = obs.estimate(z, mem, T)
        exact = slope * (t - tau * (1.0 - math.exp(-t / tau)))
        assert est[0] == pytest.approx(exact, rel=1e-9, abs=1e-12), k
        assert est[1] == pytest.approx(0.0, abs=1e-15)


def test_the_observer_starts_in_the_steady_state():
    rng = np.random.default_rng(4)
    z, _ = _point(rng)
    est, mem = RM.SlipObserver(P).estimate(z[:8], None, T)
    assert est == pytest.approx(RM.kinematic_slip(z, P)) and mem.alpha_hat == est


def test_the_observer_follows_the_plants_transient_slip():
    """On the two-track plant (load-dependent σ, per-wheel slip, nonlinear tyres in the
    linear range) steered by a 2 Hz sine of 1°, the observer's α̂' tracks the plant's mean
    transient slip per axle to within 1.5 % of its amplitude (measured 0.5 %); the kinematic
    slip, which leads it by σ/v_x, misses it by ten times more (measured 20×)."""
    veh = load_vehicle_params()
    sim = Simulator(veh, ConstantRoad(1.0), InitialState(speed=V))
    obs = RM.SlipObserver(MpcConfig().model_params())
    mem = None
    err_obs, err_kin, amp = [], [], []
    torque = np.full(4, 18.0)                          # about the road load at 60 km/h
    for k in range(150):
        out = sim.outputs()
        z = np.array([out.vy, out.vx, 0.0, out.yaw_rate, 0.0, 0.0, out.steer_front,
                      out.steer_rear])
        est, mem = obs.estimate(z, mem, T)
        kin = RM.kinematic_slip(z, obs.params)
        y = sim.state()
        truth = (0.5 * (y[State.ALPHA_FL] + y[State.ALPHA_FR]),
                 0.5 * (y[State.ALPHA_RL] + y[State.ALPHA_RR]))
        if k >= 50:                                    # after the start-up transient
            for i in range(2):
                err_obs.append(est[i] - truth[i])
                err_kin.append(kin[i] - truth[i])
                amp.append(truth[i])
        d = math.radians(1.0) * math.sin(2 * math.pi * 2.0 * k * T)
        sim.advance(d, -0.3 * d, torque, T)
    rms = lambda e: float(np.sqrt(np.mean(np.square(e))))          # noqa: E731
    assert rms(err_obs) < 0.015 * np.max(np.abs(amp)), (rms(err_obs), np.max(np.abs(amp)))
    assert rms(err_obs) < 0.1 * rms(err_kin), (rms(err_obs), rms(err_kin))


def _straight(n=3001, length=300.0):
    x = np.linspace(0, length, n)
    return Reference.from_arrays(x, np.zeros(n), np.zeros(n), np.zeros(n), np.full(n, V))


def _sample(k, steer=0.0):
    return VehicleSample(V * T * k, 0.2, 0.0, V, 0.05, 0.02, steer_front=steer)


def test_the_controller_commits_the_observers_memory_only_with_a_step():
    cfg = MpcConfig(weights_mode="fixed", horizons_mode="fixed", qp_prebuild=False)
    assert cfg.prediction_model == "single_track_relaxation"
    ctrl = MpcController(cfg)
    ref = _straight()
    ctrl.step(0.0, _sample(0), ref)
    mem = ctrl.model_memory
    assert isinstance(mem, RM.ObserverMemory)
    with pytest.raises(ValueError, match="state"):
        ctrl.step(T, dataclasses.replace(_sample(1), vy=math.nan), ref)
    assert ctrl.model_memory is mem                    # a step that raised changed nothing
    ctrl.step(T, _sample(1, steer=0.01), ref)
    assert ctrl.model_memory is not mem
    ctrl.reset()
    assert ctrl.model_memory is None
    # a new model forgets the old one's estimate; an equal one keeps it
    ctrl.step(0.0, _sample(0), ref)
    mem = ctrl.model_memory
    ctrl.update_config(dataclasses.replace(cfg, q_y=20.0))
    assert ctrl.model_memory is mem
    ctrl.update_config(dataclasses.replace(cfg, prediction_model="single_track_actuators"))
    assert ctrl.model_memory is None


def test_a_reset_controller_answers_as_a_new_one():
    cfg = MpcConfig(weights_mode="fixed", horizons_mode="fixed", qp_prebuild=False)
    ref = _straight()
    a = MpcController(cfg)
    for k in range(5):
        a.step(k * T, _sample(k, 0.01 * k), ref)
    a.reset()
    b = MpcController(cfg)
    ra, rb = a.step(0.0, _sample(0), ref), b.step(0.0, _sample(0), ref)
    assert ra.delta_front == rb.delta_front and ra.delta_rear == rb.delta_rear


def test_forward_euler_is_refused_with_the_relaxation_model():
    with pytest.raises(ValueError, match="relaxation"):
        MpcConfig(prediction_model="single_track_relaxation", prediction_discretisation="euler")
    with pytest.raises(ValueError, match="relaxation_length"):
        RM.SlipObserver(dataclasses.replace(P, relaxation_length_front_m=0.0))


def test_the_observers_linear_form_reproduces_the_observer():
    """observer_state_space (what the margins close the loop with) against SlipObserver
    itself, driven by a random kinematic slip (v_y at zero yaw rate and steer): the same
    estimates to 1e-12 on both axles."""
    p = MpcConfig().model_params()
    obs = RM.SlipObserver(p)
    rng = np.random.default_rng(5)
    dt, vx = 0.01, 16.7
    alpha = rng.normal(0.0, 0.02, 200)
    zeta = np.zeros(RM.N_STATE_RELAX)
    zeta[StateIdx.VX] = vx
    forms = [RM.observer_state_space(dt, vx, s) for s in (p.relaxation_length_front_m,
                                                          p.relaxation_length_rear_m)]
    mem, m = None, None
    for k, al in enumerate(alpha):
        zeta[StateIdx.VY] = -al * vx                       # α_f = α_r = −v_y / v_x
        est, mem = obs.estimate(zeta, mem, dt)
        if k == 0:                                         # starts at α̂' = α
            e_g = [RM.hold_coefficients(dt, vx, s) for s in (p.relaxation_length_front_m,
                                                             p.relaxation_length_rear_m)]
            m = [e * al + (g - e) * al for e, g in e_g]
            continue
        for j, (a_, b_, c_, d_) in enumerate(forms):
            assert c_ * m[j] + d_ * al == pytest.approx(est[j], abs=1e-12)
            m[j] = a_ * m[j] + b_ * al


def test_the_observer_at_zero_period_holds_its_estimate():
    """dt = 0 (x = T v_x/σ = 0): e = g = 1, the limit of the hold, not a division by zero;
    the estimate then stays where it was."""
    assert RM.hold_coefficients(0.0, V, P.relaxation_length_front_m) == (1.0, 1.0)
    rng = np.random.default_rng(6)
    z, _ = _point(rng)
    est, mem = RM.SlipObserver(P).estimate(z[:8], None, T)
    z2 = z.copy()
    z2[StateIdx.VY] += 0.3
    again, _ = RM.SlipObserver(P).estimate(z2[:8], mem, 0.0)
    assert again == pytest.approx(est, abs=1e-15)
