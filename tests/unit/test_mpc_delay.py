"""Delay compensation: the buffer of commands sent, the prediction over the delay, and the
closed loop against a plant whose commands act N periods late."""

import math

import numpy as np
import pytest

from fourws_mpc.core import delay as D
from fourws_mpc.core.config import MpcConfig
from fourws_mpc.core.controller import MpcController, VehicleSample
from fourws_mpc.core.delay import (
    CommandBuffer,
    channel_delays,
    register_schedule,
)
from fourws_mpc.core.model import StateIdx, dynamics
from fourws_mpc.core.reference import Reference

V = 60 / 3.6
DT = 0.01


def _straight(n=4001, length=400.0, v=V):
    x = np.linspace(0, length, n)
    return Reference.from_arrays(x, np.zeros(n), np.zeros(n), np.zeros(n), np.full(n, v))


def test_dead_time_delays_the_steering_only():
    assert channel_delays(1, 0.04, DT) == (5, 5, 1)
    assert channel_delays(0, 0.0, DT) == (0, 0, 0)
    assert channel_delays(2, 0.014, DT) == (3, 3, 2)       # rounded to whole periods


def test_schedule_takes_sent_commands_and_holds_the_last_for_a_shorter_delay():
    s = register_schedule((3, 3, 1))
    # step k+j gets u(k − N_c + j) = register N_c − j − 1; Mz after its delay: u(k−1)
    np.testing.assert_array_equal(s, [[2, 2, 0], [1, 1, 0], [0, 0, 0]])
    buf = CommandBuffer(3, np.zeros(3))
    for k in range(1, 5):
        buf.push(np.array([k, 10 * k, 100 * k], float))      # u(k−1) = 4, u(k−2) = 3, ...
    np.testing.assert_array_equal(buf.applied(s), [[2, 20, 400], [3, 30, 400], [4, 40, 400]])


def _cfg(**kw):
    base = dict(weights_mode="fixed", horizons_mode="fixed", qp_prebuild=False,
                scale_y_m=0.02, np_baseline=20, nc_baseline=6)
    base.update(kw)
    return MpcConfig(**base)


@pytest.mark.parametrize("model", ["single_track_actuators", "single_track_relaxation"])
def test_the_state_predicted_over_the_delay_is_the_explicit_simulation_with_the_sent_commands(
        model):
    cfg = _cfg(prediction_model=model, prediction_discretisation="zoh",
               input_delay_periods=2, steer_dead_time_s=0.03)       # δ: 5 periods, Mz: 2
    ctrl = MpcController(cfg)
    seen = []
    solve = ctrl.qp.solve

    def spy(Ak, Bk, dk, zeta0, *args, **kw):
        seen.append((Ak, Bk, dk, zeta0.copy()))
        return solve(Ak, Bk, dk, zeta0, *args, **kw)

    ctrl.qp.solve = spy
    ref = _straight()
    sent = []
    rng = np.random.default_rng(3)
    for k in range(8):
        memory = ctrl.model_memory                  # the observer's, before step k
        s = VehicleSample(V * DT * k, 0.3 - 0.01 * k, 0.01, V, rng.uniform(-0.1, 0.1),
                          rng.uniform(-0.05, 0.05), rng.uniform(-0.02, 0.02),
                          rng.uniform(-0.01, 0.01))
        r = ctrl.step(k * DT, s, ref)
        sent.append(np.array([r.delta_front, r.delta_rear, r.yaw_moment]))
    # the last step, by hand: ζ0 in the path frame, then 5 steps of eq. (4) with the commands
    # sent at k − N_c + j, Mz held at u(k−1) once its 2 periods are over
    k = 7
    X, Y, phi = ref.to_path_frame(ref.nearest(s.x, s.y), s.x, s.y, s.yaw)
    z, _ = ctrl.model.measured_state(np.array([s.vy, s.vx, phi, s.yaw_rate, Y, X]),
                                     s.steer_front, s.steer_rear, memory, DT)
    assert z.shape == (ctrl.model.n_state,)
    Ak, Bk, dk, got = seen[k]
    delays = (5, 5, 2)
    for j in range(5):
        u = np.array([sent[k - delays[c] + j][c] if k - delays[c] + j < k else sent[k - 1][c]
                      for c in range(3)])
        z = Ak @ z + Bk @ u + dk
    np.testing.assert_allclose(got, z, rtol=1e-12, atol=1e-12)


def _run(cfg, plant_delay, steps=250, y0=0.3):
    """Nonlinear eq. (1) at constant speed (1 ms Euler substeps) whose commands act
    ``plant_delay`` periods after they are computed (zeros before); lateral offset per step."""
    ctrl = MpcController(cfg)
    p = ctrl.model.params
    ref = _straight()
    z = np.array([0.0, V, 0.0, 0.0, y0, 0.0])
    queue = [np.zeros(3)] * plant_delay
    y = []
    for k in range(steps):
        s = VehicleSample(z[StateIdx.X], z[StateIdx.Y], z[StateIdx.PHI], V, z[StateIdx.VY],
                          z[StateIdx.R])
        r = ctrl.step(k * DT, s, ref)
        queue.append(np.array([r.delta_front, r.delta_rear, r.yaw_moment]))
        u = queue.pop(0)
        for _ in range(10):
            z = z + 0.001 * dynamics(z, u, p)
        z[StateIdx.VX] = V
        y.append(z[StateIdx.Y])
    return np.array(y)


@pytest.mark.parametrize("n", [3, 6])
def test_compensation_recovers_the_undelayed_response_on_a_delayed_plant(n):
    """The compensated loop on a plant n periods late follows the undelayed loop shifted by
    n periods; without compensation it rings (and beyond a few periods diverges)."""
    ideal = _run(_cfg(), 0)
    comp = _run(_cfg(input_delay_periods=n), n)
    plain = _run(_cfg(), n)
    dev_comp = np.max(np.abs(comp[n:] - ideal[:-n]))
    dev_plain = np.max(np.abs(plain[n:] - ideal[:-n]))
    assert dev_comp < 0.1 * dev_plain
    assert dev_comp < 0.01                                  # m, of a 0.3 m offset
    assert abs(comp[-1]) < 0.01 and math.isfinite(dev_plain)


def test_the_buffer_is_committed_with_the_step_resized_with_the_config_and_reset():
    ctrl = MpcController(_cfg(input_delay_periods=2))
    ref = _straight()
    sent = []
    for k in range(3):
        r = ctrl.step(k * DT, VehicleSample(V * DT * k, 0.2, 0.0, V, 0.0, 0.0), ref)
        sent.append([r.delta_front, r.delta_rear, r.yaw_moment])
    np.testing.assert_array_equal(ctrl.sent.registers, [sent[2], sent[1]])
    with pytest.raises(ValueError):                  # a step that raises commits nothing
        ctrl.step(0.03, VehicleSample(math.nan, 0.2, 0.0, V, 0.0, 0.0), ref)
    np.testing.assert_array_equal(ctrl.sent.registers, [sent[2], sent[1]])
    ctrl.update_config(_cfg(input_delay_periods=3))
    np.testing.assert_array_equal(ctrl.sent.registers, [sent[2], sent[1], sent[1]])
    ctrl.reset()
    assert not ctrl.sent.registers.any() and ctrl.sent.registers.shape == (3, 3)


def test_hard_bounds_are_relaxed_to_where_the_compensated_qp_starts():
    """"No worse than now" must mean the state the QP starts from: after a compensated delay
    the predicted |r| can exceed both the bound and the measured |r|; relaxing to the
    measurement alone left such QPs infeasible (fallback on every one of these starts). With
    the steering lag in the prediction the angle keeps moving after the start, and a QP that
    is infeasible with the hard bounds is solved without them (said in the status)."""
    from fourws_bringup.core.configs import load_mpc_config
    from fourws_mpc.core.controller import MpcController, VehicleSample
    from fourws_sim.core.scenario import load_scenario

    p = load_scenario("dlc_60_mu05").path
    cfg = load_mpc_config("improved", {"input_delay_periods": 10})
    ref = cfg.reference(p.x, p.y, p.yaw, p.curvature, p.speed)
    for u in (0.1, 0.15):                      # front steer already sent, held over the delay
        for r in (0.0, 0.1, 0.2, 0.3):
            c = MpcController(cfg)
            c.reset(u_prev=np.array([u, 0.0, 0.0]))
            res = c.step(0.0, VehicleSample(x=10.0, y=0.0, yaw=0.0, vx=16.7, vy=0.0,
                                            yaw_rate=r), ref, mu=0.5)
            assert not res.fallback and res.solver_status.startswith("optimal"), (u, r)


def test_forward_euler_of_a_steering_lag_shorter_than_two_periods_is_refused():
    from fourws_mpc.core.config import MpcConfig

    with pytest.raises(ValueError, match="prediction_discretisation: zoh"):
        MpcConfig(prediction_model="single_track_actuators", prediction_discretisation="euler",
                  steer_front_time_constant_s=0.015)
    MpcConfig(prediction_model="single_track_actuators", prediction_discretisation="zoh",
              steer_front_time_constant_s=0.015)


def test_the_linear_form_of_the_delay_prediction_is_the_recursion():
    """The margins' form (ζ and the registers as columns of a linear map) gives what the
    controller computes from its buffer, for every split of the delay between channels."""
    rng = np.random.default_rng(3)
    n = 6
    Ak, Bk = np.eye(n) + 0.05 * rng.standard_normal((n, n)), rng.standard_normal((n, 3))
    for delays in ((1, 1, 1), (3, 3, 1), (2, 2, 0), (4, 4, 2)):
        schedule = D.register_schedule(delays)
        n_reg = max(delays)
        buf = D.CommandBuffer(n_reg, np.zeros(3))
        for _ in range(n_reg):
            buf.push(rng.standard_normal(3))
        zeta = rng.standard_normal(n)
        direct = D.predict_over_delay(Ak, Bk, np.zeros(n), zeta, buf.applied(schedule))
        # the map from x = [ζ; r_0; r_1; ...] to ζ(k + N_d)
        m = n + 3 * n_reg
        regs = np.zeros((n_reg, 3, m))
        for i in range(n_reg):
            regs[i, :, n + 3 * i:n + 3 * i + 3] = np.eye(3)
        Z0 = np.hstack([np.eye(n), np.zeros((n, 3 * n_reg))])
        M = D.predict_over_delay(Ak, Bk, np.zeros(n), Z0, D.applied_commands(regs, schedule))
        x = np.concatenate([zeta, buf.registers.reshape(-1)])
        np.testing.assert_allclose(M @ x, direct, rtol=1e-12, atol=1e-12)
