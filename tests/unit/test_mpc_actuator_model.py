"""Actuator-aware prediction model: exact Jacobians of eq. (1) + steering lag, the zero-order
hold, the dimension-generic QP, and the measured road-wheel angles in the controller."""

import math

import numpy as np
import pytest
from numdiff_helpers import central_jacobian

from fourws_mpc.core import actuator_model as M
from fourws_mpc.core import qp as Q
from fourws_mpc.core.config import MpcConfig
from fourws_mpc.core.controller import MpcController, VehicleSample
from fourws_mpc.core.model import InputIdx, ModelParams, StateIdx, dynamics
from fourws_mpc.core.prediction_model import (
    PREDICTION_MODELS,
    affine_euler,
    affine_zoh,
    make_prediction_model,
)
from fourws_mpc.core.reference import Reference

P = ModelParams(c_cf=27994.0, c_cr=29999.0)
A_ = M.ActIdx
T = 0.01


def _point(seed):
    rng = np.random.default_rng(seed)
    z = np.array([rng.uniform(-1, 1), rng.uniform(5, 30), rng.uniform(-3, 3),
                  rng.uniform(-0.6, 0.6), rng.uniform(-50, 50), rng.uniform(-50, 200),
                  rng.uniform(-0.3, 0.3), rng.uniform(-0.15, 0.15)])
    u = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.15, 0.15), rng.uniform(-1500, 1500)])
    return z, u


@pytest.mark.parametrize("seed", range(12))
def test_extended_jacobians_match_central_differences(seed):
    z, u = _point(seed)
    f0, A, B = M.jacobians(z, u, P)
    np.testing.assert_allclose(f0, M.dynamics(z, u, P))
    hz = np.array([1e-6, 1e-6, 1e-7, 1e-7, 1e-5, 1e-5, 1e-7, 1e-7])
    hu = np.array([1e-7, 1e-7, 1e-3])
    np.testing.assert_allclose(A, central_jacobian(lambda x: M.dynamics(x, u, P), z, hz),
                               rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(B, central_jacobian(lambda v: M.dynamics(z, v, P), u, hu),
                               rtol=1e-5, atol=1e-8)


def test_the_tyres_see_the_actual_angles_and_the_actuators_lag():
    z, u = _point(3)
    f = M.dynamics(z, u, P)
    ua = np.array([z[A_.DF_ACT], z[A_.DR_ACT], u[InputIdx.MZ]])
    np.testing.assert_array_equal(f[:6], dynamics(z[:6], ua, P))    # eq. (1) at δ_act
    assert f[A_.DF_ACT] == pytest.approx((u[0] - z[A_.DF_ACT]) / P.steer_front_time_constant_s)
    assert f[A_.DR_ACT] == pytest.approx((u[1] - z[A_.DR_ACT]) / P.steer_rear_time_constant_s)
    # with the actuators settled on the command the body moves as in eq. (1)
    z[A_.DF_ACT], z[A_.DR_ACT] = u[0], u[1]
    np.testing.assert_array_equal(M.dynamics(z, u, P)[:6], dynamics(z[:6], u, P))


def _rk4_affine(At, Bt, c, z, u, dt, n=400):
    h = dt / n
    f = lambda x: At @ x + Bt @ u + c  # noqa: E731
    for _ in range(n):
        k1 = f(z)
        k2 = f(z + 0.5 * h * k1)
        k3 = f(z + 0.5 * h * k2)
        k4 = f(z + h * k3)
        z = z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return z


def test_zero_order_hold_is_exact_for_the_linearisation_and_euler_is_not():
    z0, u0 = _point(5)
    f0, At, Bt = M.jacobians(z0, u0, P)
    Ak, Bk, dk = affine_zoh(f0, At, Bt, z0, u0, T)
    z, u = z0 + 0.01 * np.arange(8), u0 + np.array([0.01, -0.005, 50.0])
    exact = _rk4_affine(At, Bt, f0 - At @ z0 - Bt @ u0, z, u, T)
    np.testing.assert_allclose(Ak @ z + Bk @ u + dk, exact, rtol=1e-9, atol=1e-9)
    # the lag's pole: e^{−T/τ} (ZOH) against 1 − T/τ (Euler)
    tau = P.steer_front_time_constant_s
    assert Ak[A_.DF_ACT, A_.DF_ACT] == pytest.approx(math.exp(-T / tau))
    assert Bk[A_.DF_ACT, InputIdx.DF] == pytest.approx(1 - math.exp(-T / tau))
    Ae, _, _ = affine_euler(f0, At, Bt, z0, u0, T)
    assert Ae[A_.DF_ACT, A_.DF_ACT] == pytest.approx(1 - T / tau)
    # Euler is eq. (4): one Euler step of the nonlinear model at the operating point
    A1, B1, d1 = affine_euler(f0, At, Bt, z0, u0, T)
    np.testing.assert_allclose(A1 @ z0 + B1 @ u0 + d1, z0 + T * f0, rtol=1e-12)


def test_models_are_registered_and_build_their_measured_state():
    assert {"single_track", "single_track_actuators"} <= set(PREDICTION_MODELS)
    m = make_prediction_model("single_track_actuators", P, "zoh")
    z, memory = m.measured_state(np.arange(6.0), 0.1, -0.05)
    assert m.n_state == 8 and z.shape == (8,) and memory is None
    assert z[A_.DF_ACT] == 0.1 and z[A_.DR_ACT] == -0.05
    assert z[StateIdx.X] == 5.0                           # ζ's indices keep their meaning
    s = make_prediction_model("single_track", P)
    assert s.n_state == 6 and s.measured_state(np.arange(6.0), 0.1, 0.0)[0].shape == (6,)
    with pytest.raises(ValueError, match="prediction_discretisation"):
        make_prediction_model("single_track", P, "tustin")


def _bounds():
    return Q.QpBounds(du_max=np.array([math.radians(0.8), math.radians(0.6), 300.0]),
                      u_max=np.array([math.radians(30), math.radians(10), 1500.0]),
                      enabled=np.array([True, True, True]), vy_max=1.0, r_max=0.5,
                      band_phi=10.0, band_y=10.0, state_bounds=False)


def test_qp_takes_the_state_dimension_from_the_model():
    """An actuator lag of 0.1 ms (settled within one period) predicts what eq. (1) predicts
    with the same hold: the QP on the 8-state model gives the 6-state model's answer, in the
    same sparsity pattern."""
    fast = ModelParams(steer_front_time_constant_s=1e-4, steer_rear_time_constant_s=1e-4)
    z6 = np.array([0.05, 60 / 3.6, 0.01, 0.02, 0.3, 0.0])
    u = np.array([0.01, 0.002, 0.0])
    s6 = make_prediction_model("single_track", fast, "zoh")
    s8 = make_prediction_model("single_track_actuators", fast, "zoh")
    z8, _ = s8.measured_state(z6, u[0], u[1])
    qp = Q.MpcQp()
    args = (np.zeros((12, 2)), 12, 6, np.array([50.0, 40.0]), np.array([1e4, 1e4, 1e-4]),
            1e3, _bounds())
    a = qp.solve(*s6.discretise(z6, u, T), z6, u, *args)
    b = qp.solve(*s8.discretise(z8, u, T), z8, u, *args)
    assert a.ok and b.ok and list(qp.instances) == [(12, 6)]
    scale = np.abs(a.u).max(axis=0)           # per input: the lag costs ~1 % of a period
    assert np.all(np.abs(b.u - a.u) <= 0.02 * scale)


def _straight(v, n=3001, length=300.0):
    x = np.linspace(0, length, n)
    return Reference.from_arrays(x, np.zeros(n), np.zeros(n), np.zeros(n), np.full(n, v))


def test_the_controller_reads_the_measured_road_wheel_angles_only_with_actuator_states():
    v = 60 / 3.6
    ref = _straight(v)
    base = dict(weights_mode="fixed", horizons_mode="fixed", qp_prebuild=False)
    for model, differs in (("single_track", False), ("single_track_actuators", True),
                           ("single_track_relaxation", True)):
        cfg = MpcConfig(prediction_model=model, prediction_discretisation="zoh", **base)
        out = []
        for steer in (0.0, math.radians(2.0)):
            c = MpcController(cfg)
            s = VehicleSample(0.0, 0.002, 0.0, v, 0.0, 0.0, steer_front=steer)
            out.append(c.step(0.0, s, ref).delta_front)
        assert (abs(out[0] - out[1]) > 1e-6) == differs, model
