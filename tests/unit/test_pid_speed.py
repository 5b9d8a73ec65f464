"""Speed PID (eq. 24) in closed loop with a longitudinal model written here as the oracle:

    m v̇ = T_m / r − c v² − f_r m g,     2 τ² T̈_m + 2 τ Ṫ_m + T_m = T_cmd  (eq. 32, τ = 0.02 s)

integrated with 1 ms steps between the 10 ms controller samples (zero-order hold).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from fourws_torque_alloc.core.pid import PidOutput, SpeedPid, SpeedPidConfig

M, C_DRAG, F_ROLL, G = 750.0, 0.36, 0.015, 9.81
TAU_MOTOR = 0.02
DT = 0.01
KMH = 1.0 / 3.6


def road_load_n(v: float) -> float:
    return C_DRAG * v * v + F_ROLL * M * G


def simulate(cfg: SpeedPidConfig, v0: float, v_ref, duration_s: float,
             preset_integral: bool = True):
    """Return arrays of speed, saturation flag and commanded torque at the controller rate."""
    pid = SpeedPid(cfg)
    t_load = road_load_n(v0) * cfg.wheel_radius_m
    if preset_integral:
        pid.reset(road_load_n(v0))
    v, tm, tm_dot = v0, t_load, 0.0
    n = int(round(duration_s / DT))
    sub = 10
    h = DT / sub
    vs = np.empty(n)
    sat = np.empty(n, dtype=bool)
    cmd = np.empty(n)
    for k in range(n):
        out = pid.step(v_ref(k * DT), v, DT)
        vs[k], sat[k], cmd[k] = v, out.saturated, out.torque_nm
        for _ in range(sub):
            tm_ddot = (out.torque_nm - tm - 2 * TAU_MOTOR * tm_dot) / (2 * TAU_MOTOR**2)
            tm_dot += h * tm_ddot
            tm += h * tm_dot
            v += h * (tm / cfg.wheel_radius_m - road_load_n(v)) / M
    return vs, sat, cmd


@pytest.mark.parametrize("speed_kmh", [60.0, 90.0])
@pytest.mark.parametrize("anti_windup", ["back_calculation", "conditional"])
def test_zero_steady_state_error_against_road_load(speed_kmh, anti_windup):
    cfg = SpeedPidConfig(anti_windup=anti_windup)
    v_ref = speed_kmh * KMH
    # integrator starts empty: the road load is an unknown constant disturbance
    pid_vs, _, cmd = simulate(cfg, v_ref, lambda t: v_ref, 40.0, preset_integral=False)
    assert abs(pid_vs[-1] - v_ref) < 1e-4
    assert np.max(np.abs(pid_vs[-200:] - v_ref)) < 1e-4
    # the integral holds the road load: the force oracle is c v² + f_r m g
    assert cmd[-1] / cfg.wheel_radius_m == pytest.approx(road_load_n(v_ref), abs=0.5)


def overshoot_after_saturation(cfg: SpeedPidConfig) -> tuple[float, float]:
    v0, v1 = 60.0 * KMH, 90.0 * KMH
    vs, sat, _ = simulate(cfg, v0, lambda t: v1, 40.0)
    assert sat.any()
    last_sat = int(np.nonzero(sat)[0].max())
    saturated_for_s = (last_sat + 1) * DT
    return (vs[last_sat:].max() - v1) / (v1 - v0), saturated_for_s


@pytest.mark.parametrize("max_total_torque_nm", [2000.0, 800.0, 500.0])
def test_no_windup_overshoot_after_saturation(max_total_torque_nm):
    """+30 km/h step from 60 km/h. With lower torque limits the saturation lasts longer."""
    cfg = SpeedPidConfig(max_total_torque_nm=max_total_torque_nm,
                         min_total_torque_nm=-max_total_torque_nm)
    overshoot, sat_s = overshoot_after_saturation(cfg)
    windup, sat_s_none = overshoot_after_saturation(replace(cfg, anti_windup="none"))
    assert overshoot < 0.02
    assert windup > overshoot + 0.05
    assert sat_s_none > sat_s  # a wound-up integrator also holds the motors at the limit longer
    if max_total_torque_nm <= 800.0:
        assert sat_s > 1.0  # a long saturation was actually exercised


def test_output_limits_and_torque_relation():
    cfg = SpeedPidConfig()
    pid = SpeedPid(cfg)
    out = pid.step(40.0, 10.0, DT)
    assert out.saturated
    assert out.force_n == pytest.approx(cfg.max_total_torque_nm / cfg.wheel_radius_m)
    assert out.torque_nm == pytest.approx(cfg.max_total_torque_nm)
    out = pid.step(0.0, 30.0, DT)
    assert out.saturated and out.torque_nm == pytest.approx(cfg.min_total_torque_nm)
    out = pid.step(20.0, 20.0, DT)
    assert out.torque_nm == pytest.approx(out.force_n * cfg.wheel_radius_m)


def test_no_derivative_kick_on_a_reference_step():
    cfg = SpeedPidConfig(kd=200.0, anti_windup="none")
    pid = SpeedPid(cfg)
    v = 20.0
    a = pid.step(20.0, v, DT)
    b = pid.step(21.0, v, DT)  # reference step of +1 m/s, measurement constant
    assert a.d_n == 0.0 and b.d_n == 0.0
    # e was 0 on the first step, so the integral did not move: the whole change is K_p Δe.
    # A derivative on the error would add K_d Δe / dt = 20 000 N.
    assert b.force_n - a.force_n == pytest.approx(cfg.kp * 1.0, abs=1e-9)


def test_derivative_acts_on_filtered_measurement():
    cfg = SpeedPidConfig(kd=200.0, derivative_filter_tau_s=0.05)
    pid = SpeedPid(cfg)
    accel = 1.5
    out = None
    for k in range(300):  # 3 s of a ramp in the measured speed, reference constant
        out = pid.step(20.0, 15.0 + accel * k * DT, DT)
    assert out is not None
    assert out.d_n == pytest.approx(-cfg.kd * accel, rel=1e-6)
    # first-order filter: after one time constant the estimate is ~63 % of a step in accel
    pid.reset()
    outs = [pid.step(20.0, 15.0 + accel * k * DT, DT).d_n for k in range(7)]
    frac = -outs[6] / (cfg.kd * accel)
    assert 0.55 < frac < 0.75


def test_feedforward_of_reference_acceleration():
    cfg = SpeedPidConfig()
    out = SpeedPid(cfg).step(20.0, 20.0, DT, a_ref_mps2=0.5)
    assert out.ff_n == pytest.approx(cfg.mass_kg * 0.5)
    assert out.force_n == pytest.approx(cfg.mass_kg * 0.5)
    out = SpeedPid(replace(cfg, accel_feedforward=False)).step(20.0, 20.0, DT, a_ref_mps2=0.5)
    assert out.force_n == 0.0


def test_ramp_is_tracked_with_feedforward():
    cfg = SpeedPidConfig()
    v0, a = 60.0 * KMH, 1.0

    def ramp(t: float) -> float:
        return v0 + a * min(t, 5.0)

    pid = SpeedPid(cfg)
    pid.reset(road_load_n(v0))
    v, tm, tm_dot = v0, road_load_n(v0) * cfg.wheel_radius_m, 0.0
    errs = []
    for k in range(1000):
        t = k * DT
        out = pid.step(ramp(t), v, DT, a if t < 5.0 else 0.0)
        errs.append(ramp(t) - v)
        for _ in range(10):
            tm_ddot = (out.torque_nm - tm - 2 * TAU_MOTOR * tm_dot) / (2 * TAU_MOTOR**2)
            tm_dot += 1e-3 * tm_ddot
            tm += 1e-3 * tm_dot
            v += 1e-3 * (tm / cfg.wheel_radius_m - road_load_n(v)) / M
    assert np.max(np.abs(errs)) < 0.1  # m/s, a 5 m/s ramp
    assert abs(errs[-1]) < 0.01


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("arg", range(4))
def test_non_finite_inputs_raise_and_leave_state(bad, arg):
    pid = SpeedPid()
    pid.step(20.0, 19.0, DT)
    before = pid.integral_n
    args = [20.0, 19.0, DT, 0.0]
    args[arg] = bad
    with pytest.raises(ValueError, match="finite"):
        pid.step(*args)
    assert pid.integral_n == before


def test_non_positive_dt_raises():
    with pytest.raises(ValueError, match="dt_s"):
        SpeedPid().step(20.0, 19.0, 0.0)


def test_back_calculation_stable_with_tiny_tracking_time():
    cfg = SpeedPidConfig(tracking_time_s=1e-3)
    pid = SpeedPid(cfg)
    for _ in range(500):
        out = pid.step(40.0, 10.0, DT)
        assert abs(pid.integral_n) <= cfg.max_force_n + 1e-9
    assert isinstance(out, PidOutput) and out.saturated


def test_reset_clears_state():
    pid = SpeedPid()
    for _ in range(50):
        pid.step(25.0, 20.0, DT)
    pid.reset()
    assert pid.integral_n == 0.0
    assert pid.step(20.0, 20.0, DT).force_n == 0.0


def test_finite_inputs_that_overflow_raise_and_leave_the_state_unchanged():
    """vx = 1.7e308 is finite; its products are not. The integrator never takes them."""
    pid = SpeedPid(SpeedPidConfig())
    pid.step(16.0, 15.0, 0.01)
    before = (pid.integral_n, pid._v_prev, pid._dv_filt)
    with pytest.raises(ValueError, match="overflow"):
        pid.step(16.0, 1.7e308, 0.01)
    assert (pid.integral_n, pid._v_prev, pid._dv_filt) == before
    out = pid.step(16.0, 15.0, 0.01)
    assert math.isfinite(out.force_n) and math.isfinite(pid.integral_n)
