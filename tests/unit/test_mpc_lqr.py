"""The reference lateral controller: Riccati gain against an independent iteration, a stable
loop at every speed, and zero steady-state offset in a constant turn with the feed-forward."""

import numpy as np
import pytest

from fourws_mpc.core.lqr import LqrLateral, LqrWeights, dlqr_gain, error_model
from fourws_mpc.core.model import ModelParams, zoh

P = ModelParams(c_cf=27994.0, c_cr=29999.0)
DT = 0.01


def _riccati_by_iteration(Ad, Bd, Q, R, n=20000):
    """Value iteration of the discrete Riccati recursion (independent of scipy's solver)."""
    X = Q.copy()
    for _ in range(n):
        K = np.linalg.solve(R + Bd.T @ X @ Bd, Bd.T @ X @ Ad)
        X_new = Q + Ad.T @ X @ (Ad - Bd @ K)
        if np.max(np.abs(X_new - X)) <= 1e-10 * np.max(np.abs(X)):
            break
        X = X_new
    return np.linalg.solve(R + Bd.T @ X @ Bd, Bd.T @ X @ Ad)


@pytest.mark.parametrize("vx", [10.0, 60 / 3.6, 25.0])
def test_gain_equals_an_independent_riccati_solution(vx):
    A, B, _ = error_model(P, vx)
    Ad, Bd = zoh(A, B, DT)
    w = LqrWeights()
    K = dlqr_gain(Ad, Bd, w.q(), w.r())
    np.testing.assert_allclose(K, _riccati_by_iteration(Ad, Bd, w.q(), w.r()), rtol=1e-6)


@pytest.mark.parametrize("vx", [5.0, 10.0, 60 / 3.6, 25.0, 35.0])
def test_closed_loop_is_stable_with_a_margin(vx):
    A, B, _ = error_model(P, vx)
    Ad, Bd = zoh(A, B, DT)
    K = LqrLateral(P, DT).gain(vx)
    rho = max(abs(np.linalg.eigvals(Ad - Bd @ K)))
    assert rho < 0.995


def test_zoh_matches_a_fine_euler_integration():
    A, B, _ = error_model(P, 20.0)
    Ad, Bd = zoh(A, B, DT)
    x = np.array([0.1, 0.0, 0.01, 0.0])
    y = x.copy()
    for _ in range(10000):
        y = y + (DT / 10000) * (A @ y + B[:, 0] * 0.01)
    np.testing.assert_allclose(Ad @ x + Bd[:, 0] * 0.01, y, rtol=1e-3, atol=1e-8)


@pytest.mark.parametrize("vx, kappa", [(60 / 3.6, 0.01), (25.0, -0.005)])
def test_feedforward_removes_the_steady_lateral_offset_in_a_constant_turn(vx, kappa):
    ctrl = LqrLateral(P, DT)
    A, B, Bk = error_model(P, vx)
    n = A.shape[0]
    M = np.zeros((n + 2, n + 2))
    M[:n, :n], M[:n, n:n + 1], M[:n, n + 1:] = A, B, Bk
    E = __import__("scipy.linalg").linalg.expm(M * DT)
    Ad, Bd, Bkd = E[:n, :n], E[:n, n:n + 1], E[:n, n + 1:]
    x = np.zeros(n)
    for _ in range(3000):
        d = ctrl.steer(x, vx, kappa)
        x = Ad @ x + Bd[:, 0] * d + Bkd[:, 0] * vx * kappa
    assert abs(x[0]) < 1e-6                     # the feed-forward's promise
    without = np.zeros(n)
    K = ctrl.gain(vx)
    for _ in range(3000):
        without = Ad @ without - Bd[:, 0] * (K @ without)[0] + Bkd[:, 0] * vx * kappa
    assert abs(without[0]) > 1e-3               # and feedback alone leaves an offset


def test_lqr_ff_preset_tracks_the_ideal_paper_lane_change_within_centimetres():
    from fourws_bringup.core.closed_loop import run_closed_loop

    log = run_closed_loop("dlc_60_mu05", "lqr_ff")
    m = log.metrics()
    assert log.completed, log.reason
    assert m["max_abs_lateral_error_m"] < 0.03
    assert np.all(log.mpc["delta_rear"] == 0.0) and np.all(log.mpc["yaw_moment"] == 0.0)
    assert log.allocation == "equal"


def test_lqr_ff_respects_the_steering_actuator_limits():
    from fourws_mpc.core.config import MpcConfig
    from fourws_mpc.core.controller import VehicleSample
    from fourws_mpc.core.laws import make_controller

    cfg = MpcConfig(law="lqr_ff", controller="lqr_ff", use_rear_steer=False, use_dyc=False,
                    weights_mode="fixed", horizons_mode="fixed", qp_prebuild=False)
    ctrl = make_controller(cfg)
    x = np.linspace(0, 300, 3001)
    ref = cfg.reference(x, np.zeros_like(x), np.zeros_like(x), np.zeros_like(x),
                        np.full_like(x, 15.0))
    r = ctrl.step(0.0, VehicleSample(0.0, 1.0, 0.0, 15.0, 0.0, 0.0), ref)   # 1 m off
    assert abs(r.delta_front) == pytest.approx(np.radians(cfg.max_dsteer_front_deg))
    ctrl.reset()
    assert np.array_equal(ctrl.u_prev, np.zeros(3))


def test_lqr_ff_refuses_a_non_finite_previous_command_and_keeps_its_state():
    from fourws_mpc.core.config import MpcConfig
    from fourws_mpc.core.controller import VehicleSample
    from fourws_mpc.core.laws import make_controller

    cfg = MpcConfig(law="lqr_ff", controller="lqr_ff", use_rear_steer=False, use_dyc=False,
                    weights_mode="fixed", horizons_mode="fixed", qp_prebuild=False,
                    input_delay_periods=2)
    ctrl = make_controller(cfg)
    x = np.linspace(0, 300, 3001)
    ref = cfg.reference(x, np.zeros_like(x), np.zeros_like(x), np.zeros_like(x),
                        np.full_like(x, 15.0))
    ctrl.step(0.0, VehicleSample(0.0, 0.2, 0.0, 15.0, 0.0, 0.0), ref)
    before = ctrl.u_prev.copy()
    for bad in ([np.nan, 0.0, 0.0], [0.01, np.inf, 0.0], [0.0, 0.0]):
        with pytest.raises(ValueError):
            ctrl.reset(np.array(bad))
        assert np.array_equal(ctrl.u_prev, before)
    r = ctrl.step(0.01, VehicleSample(0.15, 0.2, 0.0, 15.0, 0.0, 0.0), ref)
    assert np.isfinite(r.delta_front)



def test_lqr_ff_keeps_its_config_when_a_new_one_fails_to_build(monkeypatch):
    import fourws_mpc.core.lqr_controller as L
    from fourws_mpc.core.config import MpcConfig
    from fourws_mpc.core.laws import make_controller

    cfg = MpcConfig(law="lqr_ff", controller="lqr_ff", use_rear_steer=False, use_dyc=False,
                    weights_mode="fixed", horizons_mode="fixed", qp_prebuild=False)
    ctrl = make_controller(cfg)
    law, model, delays = ctrl.law, ctrl.model, ctrl._delays

    def broken(*_a, **_k):
        raise ValueError("no such model here")

    monkeypatch.setattr(L, "make_prediction_model", broken)
    other = MpcConfig(**{**vars(cfg), "lqr_e1_max_m": 0.2, "input_delay_periods": 2,
                         "prediction_model": "single_track"})
    with pytest.raises(ValueError, match="no such model"):
        ctrl.update_config(other)
    assert ctrl.cfg == cfg and ctrl.law is law and ctrl.model is model
    assert ctrl._delays == delays
