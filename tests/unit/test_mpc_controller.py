"""MPC controller: closed loop on the nonlinear eq. (1) model, fallback, input checks."""

import dataclasses
import math

import numpy as np
import pytest

from fourws_mpc.core.config import MpcConfig
from fourws_mpc.core.controller import STATE_BOUNDS_DROPPED, MpcController, VehicleSample
from fourws_mpc.core.cost_scaling import effective_weights
from fourws_mpc.core.model import ModelParams, StateIdx, dynamics
from fourws_mpc.core.qp import QpSolution
from fourws_mpc.core.reference import Reference

V = 15.0


def _straight(n=3001, length=300.0, v=V):
    x = np.linspace(0, length, n)
    return Reference.from_arrays(x, np.zeros(n), np.zeros(n), np.zeros(n), np.full(n, v))


def _cfg(**kw):
    """The paper's MPC (eq. (1)-(4), forward Euler): the plant here is eq. (1) itself."""
    base = dict(weights_mode="fixed", horizons_mode="fixed", use_dyc=False,
                qp_prebuild=False, prediction_model="single_track",
                prediction_discretisation="euler")
    base.update(kw)
    return MpcConfig(**base)


def _simulate(ctrl, ref, y0=0.3, steps=300):
    """Closed loop on the nonlinear model of eq. (1) at constant speed (the PID's job)."""
    p = ctrl.model.params
    z = np.array([0.0, V, 0.0, 0.0, y0, 0.0])
    out = []
    for k in range(steps):
        st = VehicleSample(x=z[StateIdx.X], y=z[StateIdx.Y], yaw=z[StateIdx.PHI], vx=V,
                           vy=z[StateIdx.VY], yaw_rate=z[StateIdx.R])
        r = ctrl.step(0.01 * k, st, ref)
        out.append(r)
        u = np.array([r.delta_front, r.delta_rear, r.yaw_moment])
        for _ in range(10):
            z = z + 0.001 * dynamics(z, u, p)
        z[StateIdx.VX] = V
    return z, out


@pytest.mark.parametrize("rear,dyc", [(False, False), (True, False), (True, True)])
def test_converges_to_a_straight_path_on_the_nonlinear_model(rear, dyc):
    ctrl = MpcController(_cfg(use_rear_steer=rear, use_dyc=dyc, scale_y_m=0.02,
                              scale_phi_deg=0.3, np_baseline=20, nc_baseline=6))
    z, out = _simulate(ctrl, _straight(), y0=0.3, steps=400)
    assert abs(z[StateIdx.Y]) < 0.02
    assert abs(z[StateIdx.PHI]) < math.radians(0.5)
    assert not any(r.fallback for r in out)
    for r in out:
        vals = [r.delta_front, r.delta_rear, r.yaw_moment, r.slack, r.e_s]
        assert all(math.isfinite(v) for v in vals)
        if not rear:
            assert r.delta_rear == 0.0
        if not dyc:
            assert r.yaw_moment == 0.0
        assert abs(r.delta_front) <= math.radians(30) + 1e-12
    d = np.diff([r.delta_front for r in out])
    assert np.all(np.abs(d) <= math.radians(0.8) + 1e-9)


def test_fixed_mode_keeps_horizons_and_weights():
    ctrl = MpcController(_cfg())
    _, out = _simulate(ctrl, _straight(), y0=0.5, steps=30)
    assert {(r.np, r.nc) for r in out} == {(12, 6)}
    assert {(r.q_y, r.q_phi, r.r_ddelta, r.r_dmz) for r in out} == {(10.0, 1.0, 1.0, 1.0)}
    assert out[0].lateral_error == pytest.approx(0.5, abs=1e-9)


def test_fuzzy_apcha_mode_reports_adaptive_parameters():
    ctrl = MpcController(_cfg(weights_mode="fuzzy", horizons_mode="apcha", use_dyc=True))
    _, out = _simulate(ctrl, _straight(), y0=0.4, steps=20)
    r0 = out[0]
    assert r0.np > 12                    # e_s = 0.8 > 2 ε1: N_p grows towards 28
    assert 0 < r0.q_y < 8000 and 0 < r0.r_ddelta < 80000
    assert r0.e_s == pytest.approx(0.4 / 0.5, abs=1e-6)


def test_takes_one_state_type_and_rejects_non_finite():
    ctrl = MpcController(_cfg())
    ref = _straight()
    s = VehicleSample(x=0.0, y=0.1, yaw=0.0, vx=V, vy=0.0, yaw_rate=0.0)
    r = ctrl.step(0.0, s, ref)
    assert r.lateral_error == pytest.approx(0.1)
    fields = ("x", "y", "yaw", "vx", "vy", "yaw_rate")
    for name in fields:
        bad = VehicleSample(**{k: (math.nan if k == name else getattr(s, k)) for k in fields})
        with pytest.raises(ValueError, match=name):
            ctrl.step(0.01, bad, ref)
    with pytest.raises(TypeError, match="VehicleSample"):
        ctrl.step(0.01, np.array([0.0, 0.1, 0.0, V, 0.0, 0.0]), ref)
    # anything with the six attributes converts
    assert VehicleSample.of(s) == s


def _fail(*_args, **_kwargs):
    z = np.zeros((6, 3))
    return QpSolution(False, "primal infeasible", 17, z, z, 0.0, z)


def test_failed_solve_applies_the_previous_plan_shifted_then_holds(monkeypatch):
    ctrl = MpcController(_cfg())
    ref = _straight()
    s = VehicleSample(x=0.0, y=0.4, yaw=0.0, vx=V, vy=0.0, yaw_rate=0.0)
    r = ctrl.step(0.0, s, ref)
    assert not r.fallback
    plan = ctrl.plan_u.copy()
    assert plan.shape == (6, 3)
    monkeypatch.setattr(ctrl.qp, "solve", _fail)
    got = []
    for k in range(1, 9):
        r = ctrl.step(0.01 * k, s, ref)
        assert r.fallback and r.solver_status == "primal infeasible"
        got.append([r.delta_front, r.delta_rear, r.yaw_moment])
        assert all(math.isfinite(v) for v in got[-1])
    got = np.array(got)
    np.testing.assert_allclose(got[:5], plan[1:6])          # u(k+1|k), ..., u(k+5|k)
    np.testing.assert_allclose(got[5:], np.repeat(plan[5:6], 3, axis=0))   # then held


def test_failed_first_solve_holds_the_initial_command(monkeypatch):
    ctrl = MpcController(_cfg())
    monkeypatch.setattr(ctrl.qp, "solve", _fail)
    s = VehicleSample(x=0.0, y=0.4, yaw=0.0, vx=V, vy=0.0, yaw_rate=0.0)
    r = ctrl.step(0.0, s, _straight())
    assert r.fallback
    assert (r.delta_front, r.delta_rear, r.yaw_moment) == (0.0, 0.0, 0.0)


def test_infeasible_hard_bounds_are_dropped_and_said():
    ctrl = MpcController(_cfg(np_baseline=12))
    ref = _straight()
    assert not ctrl.step(0.0, VehicleSample(0.0, 0.05, 0.0, V, 0.0, 0.0), ref, mu=1.0).fallback
    # 20° of front steer already applied: the yaw rate rises by ~0.3 rad/s per step and the
    # 0.8°/step rate limit cannot stop it below 0.85 μ g / vx = 0.11 rad/s (μ = 0.2)
    ctrl.u_prev = np.array([math.radians(20.0), 0.0, 0.0])
    r = ctrl.step(0.01, VehicleSample(0.15, 0.05, 0.0, V, 0.0, 0.1), ref, mu=0.2)
    assert not r.fallback and STATE_BOUNDS_DROPPED in r.solver_status
    assert r.delta_front == pytest.approx(math.radians(20.0 - 0.8))  # steers back at the limit


@pytest.mark.parametrize(("solver", "text"), [("daqp", "iteration limit"),
                                               ("osqp", "maximum iterations")])
def test_a_failed_solve_falls_back_to_the_previous_plan_without_nan(solver, text):
    ctrl = MpcController(_cfg(np_baseline=12, qp_solver=solver))
    ref = _straight()
    assert not ctrl.step(0.0, VehicleSample(0.0, 0.05, 0.0, V, 0.0, 0.0), ref, mu=1.0).fallback
    plan = ctrl.plan_u.copy()
    ctrl.update_config(dataclasses.replace(ctrl.cfg, qp_max_iter=1, osqp_check_termination=1))
    r = ctrl.step(0.01, VehicleSample(0.15, 0.3, 0.0, V, 0.0, 0.1), ref, mu=1.0)
    assert r.fallback and text in r.solver_status
    assert r.delta_front == pytest.approx(plan[1, 0])      # the previous plan, shifted
    assert all(math.isfinite(v) for v in (r.delta_front, r.delta_rear, r.yaw_moment))


def test_hard_bounds_relax_to_the_current_state_when_already_beyond():
    """|r| above its bound: the bound becomes "no worse than now", the QP stays feasible."""
    ctrl = MpcController(_cfg(np_baseline=12))
    ref = _straight()
    r = ctrl.step(0.0, VehicleSample(0.0, 0.0, 0.0, V, 0.0, 0.3), ref, mu=0.2)
    assert not r.fallback and r.solver_status == "optimal"      # DAQP's text, the default
    assert r.delta_front < 0.0                               # steers against the yaw rate


def test_reset_forgets_the_past():
    ctrl = MpcController(_cfg(weights_mode="fuzzy", horizons_mode="apcha"))
    _simulate(ctrl, _straight(), y0=0.6, steps=10)
    assert ctrl.n_p != 12 or ctrl.plan_u is not None
    ctrl.reset()
    assert (ctrl.n_p, ctrl.n_c) == (12, 6)
    assert ctrl.plan_u is None and np.all(ctrl.u_prev == 0.0) and ctrl.e_s_prev is None


def test_prebuild_creates_every_reachable_instance():
    cfg = MpcConfig(qp_prebuild=True)
    ctrl = MpcController(cfg)
    assert set(ctrl.qp.instances) == set(cfg.horizon_pairs())
    assert (12, 6) in ctrl.qp.instances and (30, 10) in ctrl.qp.instances
    assert all(n_p // 3 <= n_c <= max(n_p // 3, n_p // 2) for n_p, n_c in ctrl.qp.instances)


def test_model_params_follow_the_config():
    p = MpcConfig(cornering_stiffness_front_static_n_per_rad=25000.0).model_params()
    assert isinstance(p, ModelParams) and p.c_cf == 25000.0


def _states(n=120, y0=0.3):
    """A fixed sequence of measured states (the loop closed once, then replayed)."""
    ctrl = MpcController(_cfg(weights_mode="fuzzy", horizons_mode="apcha", use_dyc=True))
    ref = _straight()
    p = ctrl.model.params
    z = np.array([0.0, V, 0.0, 0.0, y0, 0.0])
    out = []
    for k in range(n):
        st = VehicleSample(x=z[StateIdx.X], y=z[StateIdx.Y], yaw=z[StateIdx.PHI], vx=V,
                           vy=z[StateIdx.VY], yaw_rate=z[StateIdx.R])
        out.append(st)
        r = ctrl.step(0.01 * k, st, ref)
        u = np.array([r.delta_front, r.delta_rear, r.yaw_moment])
        for _ in range(10):
            z = z + 0.001 * dynamics(z, u, p)
        z[StateIdx.VX] = V
    return out


def _answers(ctrl, states, ref, change_at=None, change=None):
    out = []
    for k, st in enumerate(states):
        if k == change_at:
            ctrl.update_config(change)
        r = ctrl.step(0.01 * k, st, ref)
        out.append((r.delta_front, r.delta_rear, r.yaw_moment, r.np, r.nc, r.q_y))
    return out


def test_a_reset_controller_answers_exactly_as_a_new_one():
    """A second run against the same controller (reset at its start) equals a fresh run bit
    for bit: the OSQP instances' adapted ρ and duals are forgotten too."""
    cfg = _cfg(weights_mode="fuzzy", horizons_mode="apcha", use_dyc=True, qp_prebuild=True)
    states, ref = _states(), _straight()
    ctrl = MpcController(cfg)
    first = _answers(ctrl, states, ref)
    ctrl.reset()
    assert _answers(ctrl, states, ref) == first
    assert _answers(MpcController(cfg), states, ref) == first


def test_a_parameter_change_keeps_the_controller_state():
    cfg = _cfg(weights_mode="fuzzy", horizons_mode="apcha", use_dyc=True)
    states, ref = _states(), _straight()
    base = _answers(MpcController(cfg), states, ref)
    # an equal config is a no-op: the answers do not move by a bit
    assert _answers(MpcController(cfg), states, ref, 60, MpcConfig(**vars(cfg))) == base
    # a real change from step 60 on: identical before, different after, and the state at the
    # change is the one the controller had (not a reset: the plan and horizons survive)
    ctrl = MpcController(cfg)
    _answers(ctrl, states[:60], ref)
    kept = (ctrl.u_prev.copy(), ctrl.n_p, ctrl.n_c, ctrl.e_s_prev, ctrl.plan_u.copy())
    new = MpcConfig(**{**vars(cfg), "q_y_max": 4000.0})
    ctrl.update_config(new)
    assert np.array_equal(ctrl.u_prev, kept[0]) and (ctrl.n_p, ctrl.n_c) == kept[1:3]
    assert ctrl.e_s_prev == kept[3] and np.array_equal(ctrl.plan_u, kept[4])
    changed = _answers(MpcController(cfg), states, ref, 60, new)
    assert changed[:60] == base[:60] and changed[60:] != base[60:]
    assert changed[60][5] == pytest.approx(base[60][5] / 2.0)  # Q_Y from the new maximum


def test_a_finite_extreme_state_is_refused_and_does_not_poison_the_controller():
    """x = 1e300 is finite, but it overflows the projection and the QP: the core refuses it
    before it changes anything, and the next good state is answered as if it never came."""
    ref = _straight()
    good = [VehicleSample(0.16 * k, 0.1, 0.0, V, 0.0, 0.0) for k in range(3)]
    a, b = MpcController(_cfg()), MpcController(_cfg())
    a.step(0.0, good[0], ref)
    b.step(0.0, good[0], ref)
    with pytest.raises(ValueError, match=r"x=1e\+300 \(range"):
        a.step(0.01, VehicleSample(1e300, 0.1, 0.0, V, 0.0, 0.0), ref)
    ra, rb = a.step(0.02, good[1], ref), b.step(0.02, good[1], ref)
    assert ra == rb


def test_qp_data_osqp_would_refuse_are_a_failed_solve():
    """OSQP's wrapper ignores a refused update and would solve the previous data: the MPC
    never lets it. Non-finite data give a failed solve naming the reason."""
    ctrl = MpcController(_cfg())
    c = ctrl.cfg
    zeta = np.array([0.0, V, 0.0, 0.0, 0.0, 0.0])
    A, B, d = ctrl.model.discretise(zeta, np.zeros(3), c.dt_s)
    q, r = effective_weights(c, c.q_phi, c.q_y, c.r_ddelta, c.r_dmz)
    from fourws_mpc.core.qp import QpBounds

    bounds = QpBounds(du_max=c.du_max, u_max=c.u_max, enabled=c.enabled, vy_max=1.0,
                      r_max=1.0, band_phi=0.1, band_y=0.5)
    ref_out = np.zeros((c.np_baseline, 2))
    ok = ctrl.qp.solve(A, B, d, zeta, np.zeros(3), ref_out, c.np_baseline, c.nc_baseline,
                       q, r, c.rho, bounds)
    assert ok.ok
    zeta_bad = zeta.copy()
    zeta_bad[StateIdx.Y] = 1e300
    bad = ctrl.qp.solve(A, B, d, zeta_bad, np.zeros(3), ref_out, c.np_baseline,
                        c.nc_baseline, q, r, c.rho, bounds)
    assert not bad.ok and bad.status.startswith("invalid data")


def test_an_injected_solver_is_reset_with_the_controller():
    """A reset controller answers as a new one, with an injected solver too."""
    from fourws_mpc.core.qp_solver import OsqpSolver, QpSettings

    ref = _straight()
    states = _states(40)
    solver = OsqpSolver(QpSettings())
    ctrl = MpcController(_cfg(), solver=solver)
    first = [ctrl.step(0.01 * k, s, ref).delta_front for k, s in enumerate(states)]
    ctrl.reset()
    again = [ctrl.step(0.01 * k, s, ref).delta_front for k, s in enumerate(states)]
    assert again == first
    fresh = MpcController(_cfg(qp_solver="osqp"))
    assert [fresh.step(0.01 * k, s, ref).delta_front for k, s in enumerate(states)] == first


def test_a_config_that_fails_to_apply_changes_nothing(monkeypatch):
    """update_config builds what can raise (the solver, the model, the fuzzy surfaces, the μ
    estimate) before it commits: when the last of them fails, the controller keeps its
    config, model, memory, weights, delays and solver, and answers as before."""
    import fourws_mpc.core.controller as C

    cfg = MpcConfig(prediction_model="single_track_friction", terminal_cost="lqr",
                    qp_prebuild=False)
    states, ref = _states(), _straight()
    base = _answers(MpcController(cfg), states, ref)
    ctrl = MpcController(cfg)
    _answers(ctrl, states[:30], ref)
    kept = (ctrl.model, ctrl.model_memory, ctrl.fuzzy, ctrl._grip, ctrl.qp, ctrl._delays,
            ctrl.apcha_params)

    def broken(*_a, **_k):
        raise ImportError("no such solver here")

    monkeypatch.setattr(C, "make_qp_solver", broken)
    other = MpcConfig(**{**vars(cfg), "qp_solver": "osqp", "prediction_model": "single_track",
                         "fuzzy_grid_y": 61, "input_delay_periods": 1, "apcha_eps1": 0.3})
    with pytest.raises(ImportError):
        ctrl.update_config(other)
    assert ctrl.cfg == cfg
    now = (ctrl.model, ctrl.model_memory, ctrl.fuzzy, ctrl._grip, ctrl.qp, ctrl._delays,
           ctrl.apcha_params)
    assert all(a is b or a == b for a, b in zip(now, kept, strict=True))
    monkeypatch.undo()
    rest = [ctrl.step(0.01 * k, s, ref) for k, s in enumerate(states[30:], start=30)]
    assert [(r.delta_front, r.delta_rear, r.yaw_moment) for r in rest] == \
        [(b[0], b[1], b[2]) for b in base[30:]]
