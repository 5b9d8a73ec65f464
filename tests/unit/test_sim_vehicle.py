"""Two-track plant against physics oracles: linear single-track theory in the linear range,
μ g at the limit, the friction bound, force and moment balances, load transfer, numerics.

The speed is held by a proportional law written here (force = m·k·(v_ref − v_x) plus the known
resistances); the total torque is split as the paper's allocation does with M_z = 0 (equal
halves left and right, front/rear ∝ F_z² within a side), so the drive adds no yaw moment.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fourws_common.wheels import Wheel
from fourws_sim.core.plant_io import InitialState, PlantOutputs
from fourws_sim.core.road import ConstantRoad
from fourws_sim.core.simulator import Simulator
from fourws_sim.core.vehicle_params import VehicleParams, load_vehicle_params

P = load_vehicle_params()
M, L, A, B_CG = P.mass_kg, P.wheelbase_m, P.cg_to_front_axle_m, P.cg_to_rear_axle_m
R_W = P.wheel_radius_m
K_US = P.understeer_gradient()
CF, CR = P.static_cornering_stiffness()


def split(total_nm: float, fz: np.ndarray) -> np.ndarray:
    """Equal halves left/right, front/rear ∝ F_z² within each side (eq. 31 with M_z = 0)."""
    w = fz**2
    rl = 0.5 * total_nm * w[Wheel.RL] / (w[Wheel.FL] + w[Wheel.RL])
    rr = 0.5 * total_nm * w[Wheel.RR] / (w[Wheel.FR] + w[Wheel.RR])
    return np.array([0.5 * total_nm - rl, 0.5 * total_nm - rr, rl, rr])


def hold_torque(out: PlantOutputs, v_ref: float, gain: float = 2.0) -> float:
    """Total wheel torque (N·m) of a proportional speed law with resistance feed-forward."""
    drag = 0.5 * P.air_density_kg_m3 * P.drag_coefficient * P.frontal_area_m2 * out.vx**2
    induced = abs(out.fy[Wheel.FL] + out.fy[Wheel.FR]) * abs(math.sin(out.steer_front))
    force = M * gain * (v_ref - out.vx) + drag + P.rolling_resistance_coeff * M * 9.81 + induced
    return force * R_W


def body_lateral_force(out: PlantOutputs) -> float:
    delta = np.array([out.steer_front] * 2 + [out.steer_rear] * 2)
    return float(np.sum(out.fx * np.sin(delta) + out.fy * np.cos(delta)))


def steady_turn(v: float, delta_f: float, delta_r: float = 0.0, mu: float = 1.0,
                t_end: float = 8.0, params: VehicleParams = P) -> PlantOutputs:
    sim = Simulator(params, ConstantRoad(mu), InitialState(speed=v))
    out = sim.outputs()
    for _ in range(round(t_end / 0.01)):
        out = sim.step(delta_f, delta_r, split(hold_torque(out, v), out.fz))
    return out


@pytest.mark.parametrize("rear_ratio", [0.0, -0.3, 0.3])
def test_steady_state_yaw_rate_gain_matches_linear_single_track(rear_ratio):
    """r/δ = v / (L + K_us v²) with δ = δf − δr, at 0.5 m/s², 15 m/s, μ = 1."""
    v, ay = 15.0, 0.5
    delta = (L + K_US * v * v) * ay / (v * v)
    df = delta / (1.0 - rear_ratio)
    out = steady_turn(v, df, rear_ratio * df)
    gain = out.yaw_rate / delta
    oracle = out.vx / (L + K_US * out.vx**2)
    assert abs(gain / oracle - 1.0) < 0.10, f"gain {gain:.4f}, linear theory {oracle:.4f}"
    assert abs(gain / oracle - 1.0) < 0.02  # measured ≈ 0.1 %
    assert out.ay == pytest.approx(out.vx * out.yaw_rate, rel=0.01)


def test_force_balance_in_steady_cornering():
    """m a_y equals the body-frame sum of tyre lateral forces, and m v_x r in steady state."""
    v = 15.0
    out = steady_turn(v, (L + K_US * v * v) * 3.0 / v**2)
    f_y = body_lateral_force(out)
    assert M * out.ay == pytest.approx(f_y, rel=0.03)
    assert M * out.vx * out.yaw_rate == pytest.approx(f_y, rel=0.03)
    assert out.ay == pytest.approx(3.0, rel=0.1)


def test_load_transfer_matches_the_quasi_static_formulas():
    v = 15.0
    out = steady_turn(v, (L + K_US * v * v) * 4.0 / v**2)
    eps = P.roll_stiffness_front_share
    h = P.cg_height_m
    d_front = out.fz[Wheel.FR] - out.fz[Wheel.FL]
    d_rear = out.fz[Wheel.RR] - out.fz[Wheel.RL]
    assert d_front == pytest.approx(2 * eps * M * out.ay * h / P.track_width_front_m, rel=0.02)
    assert d_rear == pytest.approx(2 * (1 - eps) * M * out.ay * h / P.track_width_rear_m,
                                   rel=0.02)
    assert out.fz.sum() == pytest.approx(M * 9.81, rel=1e-9)
    # longitudinal transfer when accelerating on a straight
    sim = Simulator(P, ConstantRoad(1.0), InitialState(speed=10.0))
    for _ in range(100):
        out = sim.step(0.0, 0.0, np.full(4, 150.0))
    static = P.static_wheel_loads_n
    rear_gain = out.fz[Wheel.RL] - static[Wheel.RL]
    assert rear_gain == pytest.approx(M * out.ax * h / (2 * L), rel=0.02)


@pytest.mark.parametrize("mu", [0.5, 1.0])
def test_lateral_acceleration_saturates_near_mu_g_and_no_tyre_exceeds_mu_fz(mu):
    """Steer ramp (1 °/s) at constant speed, to 2.5× the linear steer for μ g."""
    v = 15.0
    d_lin = (L + K_US * v * v) * mu * 9.81 / v**2
    n = round(2.5 * d_lin / math.radians(1.0) / 0.01)
    sim = Simulator(P, ConstantRoad(mu), InitialState(speed=v))
    out = sim.outputs()
    ay, steer, util, beta = [], [], [], []
    for k in range(n):
        d = math.radians(1.0) * 0.01 * (k + 1)
        out = sim.step(d, 0.0, split(hold_torque(out, v, gain=4.0), out.fz))
        ay.append(out.ay)
        steer.append(d)
        util.append(np.max(np.hypot(out.fx, out.fy) / (out.mu * out.fz)))
        beta.append(abs(out.sideslip))
    ay, steer = np.array(ay), np.array(steer)
    ratio = ay.max() / (mu * 9.81)
    assert 0.90 <= ratio <= 1.0 + 1e-6, f"a_y,max = {ratio:.3f} μg"
    assert max(util) <= 1.03, f"friction utilisation {max(util):.4f}"
    linear_gain = ay[n // 10] / steer[n // 10]
    last = slice(2 * n // 3, n)
    late_gain = (ay[last][-1] - ay[last][0]) / (steer[last][-1] - steer[last][0])
    assert late_gain < 0.1 * linear_gain, "a_y still growing with steer: not saturated"
    assert max(beta) < math.radians(10.0), "limit understeer expected with this drive split"


def test_equal_wheel_torques_on_a_straight_give_no_yaw():
    sim = Simulator(P, ConstantRoad(0.8), InitialState(speed=10.0))
    for _ in range(200):
        out = sim.step(0.0, 0.0, np.full(4, 120.0))
    assert abs(out.yaw_rate) < 1e-12 and abs(out.y) < 1e-12 and abs(out.yaw) < 1e-12
    assert out.vx > 10.0


def test_left_right_torque_difference_gives_the_yaw_moment_dT_B_over_2r():
    """At 5 m/s: M_z from the longitudinal tyre forces = (ΣT_right − ΣT_left) B/(2 r)."""
    sim = Simulator(P, ConstantRoad(1.0), InitialState(speed=5.0))
    torques = np.array([50.0, 150.0, 50.0, 150.0])
    for _ in range(30):
        out = sim.step(0.0, 0.0, torques)
    _, yw = P.wheel_positions_m()
    mz_long = float(-np.dot(yw, out.fx))
    d_t = torques[[Wheel.FR, Wheel.RR]].sum() - torques[[Wheel.FL, Wheel.RL]].sum()
    expected = d_t * P.track_width_front_m / (2 * R_W)
    assert mz_long == pytest.approx(expected, rel=0.10)
    assert out.yaw_rate > 0  # right wheels pushing harder turn the car left


def test_steady_yaw_rate_under_yaw_moment_matches_linear_single_track():
    v, mz = 10.0, 300.0
    d_t = mz * 2 * R_W / P.track_width_front_m  # ΣT_right − ΣT_left
    sim = Simulator(P, ConstantRoad(1.0), InitialState(speed=v))
    out = sim.outputs()
    for _ in range(500):
        base = split(hold_torque(out, v), out.fz)
        out = sim.step(0.0, 0.0, base + np.array([-1, 1, -1, 1]) * d_t / 4)
    # linear single-track: m v r = F_yf + F_yr ; 0 = a F_yf − b F_yr + M_z
    # F_yf = −2C_f (β + a r/v), F_yr = −2C_r (β − b r/v)
    u = out.vx
    a_mat = np.array([
        [2 * CF + 2 * CR, M * u + (2 * CF * A - 2 * CR * B_CG) / u],
        [2 * CF * A - 2 * CR * B_CG, (2 * CF * A * A + 2 * CR * B_CG * B_CG) / u],
    ])
    beta, r = np.linalg.solve(a_mat, [0.0, mz])
    assert out.yaw_rate == pytest.approx(r, rel=0.10)
    assert out.sideslip == pytest.approx(beta, rel=0.10, abs=2e-4)


def test_near_zero_speed_stays_finite():
    sim = Simulator(P, ConstantRoad(1.0), InitialState(speed=0.0))
    out = sim.step(0.0, 0.0, np.zeros(4))
    assert out.vx == 0.0 and out.x == 0.0 and np.all(out.fx == 0.0)
    for k in range(300):
        out = sim.step(math.radians(10.0), 0.0, np.full(4, 150.0 if k < 200 else -150.0))
        values = [getattr(out, f) for f in out.__dataclass_fields__]
        assert all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in values), k
    assert out.x > 0.5
    sim = Simulator(P, ConstantRoad(0.3), InitialState(speed=0.0))
    for _ in range(200):
        out = sim.step(0.0, 0.0, np.full(4, -400.0))
    assert np.isfinite(out.vx) and out.vx < 0.0


def _scripted_run(substep_s: float) -> list[PlantOutputs]:
    """Open-loop lane-change-like steer (2° sine, 2.5 s) at 20 m/s with constant torque."""
    sim = Simulator(P, ConstantRoad(0.8), InitialState(speed=20.0), substep_s=substep_s)
    outs = []
    for k in range(400):
        t = 0.01 * k
        d = math.radians(2.0) * math.sin(2 * math.pi * t / 2.5) if t < 2.5 else 0.0
        outs.append(sim.step(d, -0.3 * d, np.full(4, 40.0 + 5.0 * math.sin(t))))
    return outs


def test_halving_the_substep_changes_the_trajectory_by_less_than_a_millimetre():
    fine = _scripted_run(0.0005)
    base = _scripted_run(0.001)
    dy = max(abs(a.y - b.y) for a, b in zip(fine, base, strict=True))
    dx = max(abs(a.x - b.x) for a, b in zip(fine, base, strict=True))
    assert max(abs(o.y) for o in base) > 1.0  # the manoeuvre moved the car sideways
    assert dy < 1e-3 and dx < 1e-3, f"ΔY = {dy:.2e} m, ΔX = {dx:.2e} m"


def test_two_runs_with_the_same_commands_are_bit_identical():
    first, second = _scripted_run(0.001), _scripted_run(0.001)
    for a, b in zip(first, second, strict=True):
        for name in a.__dataclass_fields__:
            assert np.array_equal(np.asarray(getattr(a, name)), np.asarray(getattr(b, name))), name


def _single_track_step(v: float, delta: float, sigma_f: float, sigma_r: float,
                       t: np.ndarray) -> np.ndarray:
    """Yaw rate (rad/s) of the linear single-track model with first-order tyre lags (Pacejka
    2012, §7.2: (σ/v) Ḟ_y + F_y = 2C α) and the plant's first-order front steering actuator,
    after a front steer step ``delta`` (rad) at constant speed ``v``; σ = 0 means no lag."""
    from scipy.linalg import expm

    tau_s = P.steer_front_time_constant_s
    iz = P.yaw_inertia_kg_m2
    # states [v_y, r, F_yf, F_yr, δ]; F_y per axle
    a_mat = np.zeros((5, 5))
    a_mat[0] = [0.0, -v, 1.0 / M, 1.0 / M, 0.0]
    a_mat[1] = [0.0, 0.0, A / iz, -B_CG / iz, 0.0]
    for row, (c, s, lever, steer) in ((2, (2 * CF, sigma_f, A, 1.0)),
                                      (3, (2 * CR, sigma_r, -B_CG, 0.0))):
        k = v / s
        a_mat[row, :2] = [-k * c / v, -k * c * lever / v]
        a_mat[row, row] = -k
        a_mat[row, 4] = k * c * steer
    a_mat[4, 4] = -1.0 / tau_s
    b = np.zeros(5)
    b[4] = delta / tau_s
    aug = np.zeros((6, 6))
    aug[:5, :5], aug[:5, 5] = a_mat, b
    return np.array([(expm(aug * ti) @ np.r_[np.zeros(5), 1.0])[1] for ti in t])


def test_relaxation_lag_matches_single_track_theory_with_tyre_lag():
    """A small front steer step at 15 m/s: the plant's yaw rate follows linear single-track
    theory *with* first-order tyre lags of the plant's σ at static load (within 3 % of the
    steady value) and visibly not the same theory without them (σ → 0)."""
    v = 15.0
    delta = (L + K_US * v * v) * 0.5 / (v * v)
    sim = Simulator(P, ConstantRoad(1.0), InitialState(speed=v))
    out = sim.outputs()
    t, r = [], []
    for _ in range(80):
        out = sim.step(delta, 0.0, split(hold_torque(out, v), out.fz))
        t.append(out.t_s)
        r.append(out.yaw_rate)
    t_arr, r_arr = np.array(t), np.array(r)
    sig = P.relaxation_length_m(P.static_wheel_loads_n)
    assert sig[Wheel.FL] == pytest.approx(0.22, abs=0.01)  # MF 5.2 σ_α0, vehicle.yaml
    with_lag = _single_track_step(v, delta, sig[Wheel.FL], sig[Wheel.RL], t_arr)
    no_lag = _single_track_step(v, delta, 1e-4, 1e-4, t_arr)
    scale = float(np.max(np.abs(with_lag)))
    err_lag = float(np.max(np.abs(r_arr - with_lag))) / scale
    err_nolag = float(np.max(np.abs(r_arr - no_lag))) / scale
    assert err_lag < 0.03, f"plant vs theory with tyre lag: {err_lag:.3%}"
    assert err_nolag > 3 * err_lag, (err_lag, err_nolag)


def test_relaxation_leaves_the_steady_state_unchanged():
    v = 15.0
    df = (L + K_US * v * v) * 3.0 / v**2
    lagged = steady_turn(v, df)
    instant = steady_turn(v, df, params=dataclasses.replace(
        P, tyre_relaxation_peak_over_radius=0.0))
    assert lagged.yaw_rate == pytest.approx(instant.yaw_rate, rel=1e-6)
    assert lagged.ay == pytest.approx(instant.ay, rel=1e-6)
