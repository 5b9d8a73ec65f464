"""The friction-aware prediction (``axle_tyre``, ``friction_model``, ``grip``): the axle tyre
against the plant's Magic Formula, exact Jacobians, the linear limit, the friction ellipse,
the μ estimate, and the controller's grip envelope."""

import dataclasses
import math

import numpy as np
import pytest

from fourws_common.load_transfer import LoadGeometry, wheel_loads
from fourws_mpc.core import friction_model as FM
from fourws_mpc.core import relaxation_model as RM
from fourws_mpc.core.axle_tyre import force, stiffness_at_load
from fourws_mpc.core.config import MpcConfig
from fourws_mpc.core.controller import MpcController, VehicleSample
from fourws_mpc.core.grip import (
    CLAMPED_HIGH,
    CLAMPED_LOW,
    GripEstimator,
    GripMemory,
    GripSettings,
    lateral_use,
    peak_slips,
    steer_window,
    yaw_moment_bound,
)
from fourws_mpc.core.model import InputIdx, ModelParams, StateIdx
from fourws_mpc.core.reference import Reference
from fourws_sim.core.tyre import cornering_stiffness, peak_argument
from fourws_sim.core.vehicle_params import load_vehicle_params

P = ModelParams()
V = 60 / 3.6
R_ = RM.RelaxIdx
C, E = P.tyre_shape_lateral, P.tyre_curvature_lateral


def _mf(alpha, k, d):
    """The plant's pure-slip Magic Formula (tyre.py's equation), independently written."""
    b = k / (C * d)
    z = b * alpha
    return d * math.sin(C * math.atan(z - E * (z - math.atan(z))))


@pytest.mark.parametrize("alpha", [-0.3, -0.05, -0.01, 0.0, 0.002, 0.04, 0.08, 0.5])
def test_the_axle_tyre_is_the_magic_formula_and_its_slopes_are_exact(alpha):
    k, d = 56000.0, 1900.0
    f, df_da, df_dd = force(alpha, k, d, C, E)
    assert f == pytest.approx(_mf(alpha, k, d), rel=1e-12, abs=1e-9)
    h = 1e-7
    assert df_da == pytest.approx((_mf(alpha + h, k, d) - _mf(alpha - h, k, d)) / (2 * h),
                                  rel=1e-5, abs=1e-3)
    assert df_dd == pytest.approx((_mf(alpha, k, d + 1e-3) - _mf(alpha, k, d - 1e-3)) / 2e-3,
                                  rel=1e-5, abs=1e-6)


def test_small_slip_gives_the_linear_force_and_the_peak_is_mu_fz():
    k, d = 56000.0, 1900.0
    assert force(1e-5, k, d, C, E)[1] == pytest.approx(k, rel=1e-6)
    alphas = np.linspace(0.0, 0.5, 5001)
    peak = max(force(a, k, d, C, E)[0] for a in alphas)
    assert peak == pytest.approx(d, rel=1e-6)
    # beyond the peak the slope is negative: more slip, less force
    a_peak = peak_argument(C, E) * C * d / k
    assert force(1.5 * a_peak, k, d, C, E)[1] < 0.0


def _point(rng, vx=V):
    z = np.array([rng.uniform(-0.5, 0.5), vx, rng.uniform(-0.2, 0.2), rng.uniform(-0.3, 0.3),
                  rng.uniform(-1, 1), rng.uniform(0, 50), rng.uniform(-0.1, 0.1),
                  rng.uniform(-0.05, 0.05), rng.uniform(-0.12, 0.12),
                  rng.uniform(-0.12, 0.12)])
    return z, np.array([rng.uniform(-0.1, 0.1), rng.uniform(-0.05, 0.05),
                        rng.uniform(-1500, 1500)])


@pytest.mark.parametrize("mu,ax,ay", [(0.5, 0.0, 0.0), (0.9, 1.5, 6.5), (0.3, -2.0, -2.5)])
def test_jacobians_equal_central_finite_differences(mu, ax, ay):
    rng = np.random.default_rng(11)
    g = FM.Grip(mu, ax, ay)
    for _ in range(6):
        z, u = _point(rng)
        f, A, B = FM.jacobians(z, u, P, g)
        np.testing.assert_allclose(f, FM.dynamics(z, u, P, g), rtol=1e-12)
        for j in range(FM.N_STATE_FRICTION):
            h = 1e-6 * max(1.0, abs(z[j]))
            dz = np.zeros_like(z)
            dz[j] = h
            fd = (FM.dynamics(z + dz, u, P, g) - FM.dynamics(z - dz, u, P, g)) / (2 * h)
            np.testing.assert_allclose(A[:, j], fd, rtol=1e-5, atol=1e-5, err_msg=f"col {j}")
        for j in range(3):
            h = 1e-6 * max(1.0, abs(u[j]))
            du = np.zeros(3)
            du[j] = h
            fd = (FM.dynamics(z, u + du, P, g) - FM.dynamics(z, u - du, P, g)) / (2 * h)
            np.testing.assert_allclose(B[:, j], fd, rtol=1e-5, atol=1e-7)


def test_on_a_straight_without_yaw_moment_it_is_the_relaxation_model():
    """α' = 0, M_z = 0: slope K, ε = 1, ∂ε/∂M_z = 0, so the linearisation (and with it the
    margins of ``fourws margins``) equals the paper-tyre model's."""
    z = np.zeros(FM.N_STATE_FRICTION)
    z[StateIdx.VX] = V
    u = np.zeros(3)
    f1, A1, B1 = FM.jacobians(z, u, P, FM.Grip(0.5, 0.0))
    f0, A0, B0 = RM.jacobians(z, u, P)
    np.testing.assert_allclose(A1, A0, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(B1, B0, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(f1, f0, atol=1e-12)


@pytest.mark.parametrize("mu,ay", [(0.9, 6.2), (0.5, -4.4)])
def test_an_axle_under_load_transfer_is_the_plants_two_tyres(mu, ay):
    """At the quasi-static loads of a_y each axle's force is the sum of the plant's two tyres
    (their K_α(F_z) and the Magic Formula, written here) at the axle's slip, below, at and
    beyond the peak; at 0.63 g on μ 0.9 the front axle at 0.6 of its static peak slip gives
    5.5 % less than the same axle at static load."""
    v = load_vehicle_params()
    loads = wheel_loads(0.0, ay, LoadGeometry(
        v.mass_kg, v.cg_to_front_axle_m, v.cg_to_rear_axle_m, v.cg_height_m,
        v.track_width_front_m, v.track_width_rear_m, v.roll_stiffness_front_share,
        v.gravity_mps2))
    tyres = (v.tyre("front"), v.tyre("front"), v.tyre("rear"), v.tyre("rear"))
    peak_f, peak_r = peak_slips(P_CAR, mu)
    for share in (0.3, 0.6, 1.0, 2.0):
        z = np.zeros(FM.N_STATE_FRICTION)
        z[StateIdx.VX] = V
        z[R_.ALPHA_F], z[R_.ALPHA_R] = math.copysign(share, ay) * np.array([peak_f, peak_r])
        (ff, _, _), (fr, _, _), _ = FM.axle_forces(z, 0.0, P_CAR, FM.Grip(mu, 0.0, ay))
        plant = [_mf(z[R_.ALPHA_F if i < 2 else R_.ALPHA_R],
                     float(cornering_stiffness(fz, tyres[i])), mu * fz)
                 for i, fz in enumerate(loads)]
        assert ff == pytest.approx(plant[0] + plant[1], rel=1e-9)
        assert fr == pytest.approx(plant[2] + plant[3], rel=1e-9)
        if share == 0.6 and mu == 0.9:
            (f_static, _, _), _, _ = FM.axle_forces(z, 0.0, P_CAR, FM.Grip(mu, 0.0, 0.0))
            assert ff / f_static == pytest.approx(0.945, abs=0.003)


def test_a_yaw_moment_costs_lateral_grip_by_the_friction_ellipse():
    """ε(M_z) = ½[√(1 − η_L²) + √(1 − η_R²)], η = ±2 M_z/(B μ m g): a saturated axle loses
    exactly that share of its force."""
    g = FM.Grip(0.5, 0.0)
    mz = 1000.0
    eta = 2 * mz / (P.track_width_m * 0.5 * P.mass_kg * P.gravity_mps2)
    eps, deps = FM.ellipse(mz, P, g)
    assert eps == pytest.approx(math.sqrt(1 - eta ** 2), rel=1e-12)
    assert deps < 0.0
    z = np.zeros(FM.N_STATE_FRICTION)
    z[StateIdx.VX] = V
    z[R_.ALPHA_F] = z[R_.ALPHA_R] = 1e4       # the sliding limit: F = D sin(Cπ/2) ∝ D
    (f0, _, _), (r0, _, _), _ = FM.axle_forces(z, 0.0, P, g)
    (f1, _, _), (r1, _, _), _ = FM.axle_forces(z, mz, P, g)
    assert f1 / f0 == pytest.approx(eps, rel=1e-6)
    assert r1 / r0 == pytest.approx(eps, rel=1e-6)


def _car_params(**kw):
    """The MPC's model of the paper's car, from its car file (what the nodes get)."""
    v = load_vehicle_params()
    c_f, c_r = v.static_cornering_stiffness()
    values = dict(mass_kg=v.mass_kg, a_m=v.cg_to_front_axle_m, b_m=v.cg_to_rear_axle_m,
                  c_cf=c_f, c_cr=c_r, track_width_m=v.track_width_front_m,
                  cg_height_m=v.cg_height_m,
                  roll_stiffness_front_share=v.roll_stiffness_front_share,
                  tyre_stiffness_peak_load_n=(v.tyre_cornering_load_factor
                                              * v.tyre_nominal_load_n))
    return ModelParams(**{**values, **kw})


P_CAR = _car_params()


def _estimator(params=P_CAR, **kw):
    return GripEstimator(params, GripSettings(**kw))


def _cornering_state(mu, share, sign=1.0):
    """ζ_t and a_y of steady cornering with both axles at ``share`` of their static peak slip
    on a road of μ: a_y is the fixed point of the plant's four tyres (its K_α(F_z) law,
    ``tyre.cornering_stiffness``, and the Magic Formula, written here) at the quasi-static
    loads of that a_y (``load_transfer``, checked against the plant's steady loads in
    test_alloc_tyre_estimate)."""
    v = load_vehicle_params()
    g = LoadGeometry(v.mass_kg, v.cg_to_front_axle_m, v.cg_to_rear_axle_m, v.cg_height_m,
                     v.track_width_front_m, v.track_width_rear_m,
                     v.roll_stiffness_front_share, v.gravity_mps2)
    a_f, a_r = (share * a for a in peak_slips(P_CAR, mu))
    tyres = (v.tyre("front"), v.tyre("front"), v.tyre("rear"), v.tyre("rear"))
    ay = 0.0
    for _ in range(200):
        loads = wheel_loads(0.0, ay, g)
        total = sum(_mf(alpha, float(cornering_stiffness(fz, t)), mu * fz)
                    for alpha, fz, t in zip((a_f, a_f, a_r, a_r), loads, tyres, strict=True))
        ay = total / v.mass_kg
    z = np.zeros(FM.N_STATE_FRICTION)
    z[StateIdx.VX] = V
    z[R_.ALPHA_F], z[R_.ALPHA_R] = sign * a_f, sign * a_r
    return z, sign * ay


def test_mu_comes_from_the_state_when_it_carries_one():
    est, mem = _estimator().estimate(np.zeros(10), 0.0, 0.0, 0.0, 0.55, None, 0.01)
    assert (est.mu, est.source, est.note) == (0.55, "state", "")


@pytest.mark.parametrize("mu,sign", [(0.3, 1.0), (0.5, -1.0), (0.9, 1.0)])
def test_saturating_tyres_pull_the_estimate_to_the_road(mu, sign):
    e = _estimator(prior=1.0)
    z, ay = _cornering_state(mu, 0.9, sign)
    mem = None
    for _ in range(100):                                  # 1 s
        est, mem = e.estimate(z, 0.0, ay, 0.0, None, mem, 0.01)
    assert est.source == "evidence"
    assert est.mu == pytest.approx(mu, rel=1e-3)


def test_under_hard_braking_the_estimate_holds_whatever_the_lateral_forces_say():
    """|a_x| beyond 0.31 μ̂ g: the split of the longitudinal forces between the wheels is not
    known (split μ under ABS), so a lateral-force deficit is no evidence; μ̂ holds where it
    was, neither falling to the deficit's μ nor returning to the prior."""
    e = _estimator(prior=1.0)
    z, ay = _cornering_state(0.3, 0.9)
    mem = GripMemory(0.8)
    brake = -0.35 * 0.8 * P.gravity_mps2
    for _ in range(100):
        est, mem = e.estimate(z, brake, ay, 0.0, None, mem, 0.01)
    assert (est.mu, est.source) == (0.8, "held")
    est, _ = e.estimate(z, -0.25 * 0.8 * P.gravity_mps2, ay, 0.0, None, mem, 0.01)
    assert est.source == "evidence" and est.mu < 0.8             # lighter braking: evidence


def test_below_the_evidence_speed_the_estimate_holds():
    """At 5.5 m/s (the end of the split-μ braking) a 0.1 m/s lateral-velocity error is 1.0°
    of slip on both axles, enough to pass for the peak. Below ``evidence_min_speed`` μ̂ holds
    where it was, neither following the tyres (here a real μ 0.3 corner, the rule's cost)
    nor returning to the prior; a non-finite speed holds too; at the speed it follows them."""
    e = _estimator(prior=0.8, evidence_min_speed=10.0)
    z, ay = _cornering_state(0.3, 0.9)
    z[StateIdx.VX] = 5.5
    mem = GripMemory(0.6)
    for _ in range(50):
        est, mem = e.estimate(z, 0.0, ay, 0.0, None, mem, 0.01)
    assert (est.mu, est.source) == (0.6, "held")
    z[StateIdx.VX] = math.nan
    assert e.estimate(z, 0.0, ay, 0.0, None, mem, 0.01)[0].source == "held"
    z[StateIdx.VX] = 10.0
    est, _ = e.estimate(z, 0.0, ay, 0.0, None, mem, 0.01)
    assert est.source == "evidence" and est.mu < 0.6


def test_tyres_at_half_their_peak_say_nothing_and_noise_makes_no_evidence():
    """At 30 % of the peak slip the force is within the margin of the linear one; and a
    lateral acceleration of the wrong sign (noise on a straight) is never evidence."""
    e = _estimator(prior=1.0)
    z, ay = _cornering_state(0.9, 0.3)
    assert e.evidence(z, 0.0, ay, 0.0, 1.0) is None
    assert e.evidence(z, 0.0, -ay, 0.0, 1.0) is None


@pytest.mark.parametrize("fz", [0.0, 500.0, 1957.0, 3022.0, 6000.0])
def test_a_tyres_stiffness_at_load_is_the_plants(fz):
    """``stiffness_at_load`` from the static value and p_Ky2 F_z0 equals the plant tyre's
    K_α(F_z) (``tyre.cornering_stiffness``, front and rear)."""
    v = load_vehicle_params()
    static = v.static_wheel_loads_n
    peak = v.tyre_cornering_load_factor * v.tyre_nominal_load_n
    for c, fz0, tyre in ((P_CAR.c_cf, static[0], v.tyre("front")),
                         (P_CAR.c_cr, static[2], v.tyre("rear"))):
        assert stiffness_at_load(c, fz0, fz, peak) == pytest.approx(
            float(cornering_stiffness(fz, tyre)), rel=1e-9, abs=1e-9)


@pytest.mark.parametrize("mu,static_reads_below", [(0.5, 0.975), (0.9, 0.92)])
def test_the_road_reads_right_only_with_the_load_transfer(mu, static_reads_below):
    """At 0.6 of the peak slip on the plant's tyres the estimate is the road's μ; without the
    load transfer (h = 0: static loads) the outer tyre's smaller stiffness gain reads as
    saturation, and the same forces give a road too low: 3.4 % on μ 0.5 (0.46 g), 9.5 % on μ 0.9
    (0.79 g)."""
    z, ay = _cornering_state(mu, 0.6)
    assert _estimator().evidence(z, 0.0, ay, 0.0, mu) == pytest.approx(mu, rel=1e-6)
    static = _estimator(_car_params(cg_height_m=0.0)).evidence(z, 0.0, ay, 0.0, mu)
    assert static < static_reads_below * mu


def test_a_deficit_at_a_small_ask_is_no_evidence_but_a_low_road_still_shows():
    """On a straight the slip observer's error can put both axles at +0.5° while a_y reads
    0.3 m/s² (a realistic run): the linear tyres then exceed m a_y by the margin, but they ask
    for 0.17 of the grip the prior 0.8 allows, below ``evidence_min_ask`` (0.3), so it is no
    evidence (without the rule it is, at μ 0.03). A road of 0.15 at its peak slip asks for
    about 2.41 × 0.15 = 0.36 of the prior 1.0 and still shows."""
    z = np.zeros(FM.N_STATE_FRICTION)
    z[StateIdx.VX] = 8.3
    z[R_.ALPHA_F] = z[R_.ALPHA_R] = math.radians(0.5)
    ask = (2 * (P_CAR.c_cf + P_CAR.c_cr) * math.radians(0.5)
           / (0.8 * P_CAR.mass_kg * P_CAR.gravity_mps2))
    assert 0.1 < ask < 0.3
    assert _estimator(prior=0.8, evidence_min_ask=0.0).evidence(z, 0.0, 0.3, 0.0, 0.8) < 0.1
    assert _estimator(prior=0.8).evidence(z, 0.0, 0.3, 0.0, 0.8) is None
    z, ay = _cornering_state(0.15, 1.0)
    assert _estimator(prior=1.0).evidence(z, 0.0, ay, 0.0, 1.0) == pytest.approx(0.15,
                                                                               rel=0.01)


def test_without_evidence_it_returns_to_the_prior_and_never_below_the_grip_in_use():
    e = _estimator(prior=1.0, rise_time_s=1.0)
    z = np.zeros(FM.N_STATE_FRICTION)
    z[StateIdx.VX] = V
    z[R_.ALPHA_F] = 0.002                                 # linear range: says nothing
    ay = 2 * P.c_cf * 0.002 * (P.a_m + P.b_m) / (P.b_m * P.mass_kg)
    from fourws_mpc.core.grip import GripMemory
    mem = GripMemory(0.4)
    for _ in range(300):                                  # 3 time constants
        est, mem = e.estimate(z, 0.0, ay, 0.0, None, mem, 0.01)
    assert est.source == "prior"
    assert est.mu == pytest.approx(1.0 - 0.6 * math.exp(-3.0), rel=1e-3)
    est, _ = e.estimate(z, 6.0, 6.0, 0.0, None, GripMemory(0.3), 0.01)
    assert est.mu >= math.hypot(6.0, 6.0) / 9.81


@pytest.mark.parametrize("mu,note", [(0.0, CLAMPED_LOW), (-3.0, CLAMPED_LOW),
                                     (math.nan, CLAMPED_LOW), (50.0, CLAMPED_HIGH)])
def test_an_absurd_mu_is_clamped_and_flagged(mu, note):
    est, _ = _estimator(floor=0.1, ceiling=1.2).estimate(np.zeros(10), 0.0, 0.0, 0.0, mu,
                                                          None, 0.01)
    assert est.note == note
    assert est.mu == (0.1 if note == CLAMPED_LOW else 1.2)


def test_the_yaw_moment_bound_is_the_spare_longitudinal_grip():
    z = np.zeros(FM.N_STATE_FRICTION)
    z[StateIdx.VX] = V
    full = 0.5 * P.track_width_m * 0.5 * P.mass_kg * P.gravity_mps2
    assert yaw_moment_bound(z, P, 0.5, 0.0) == pytest.approx(full, rel=1e-9)
    z[R_.ALPHA_F] = peak_slips(P, 0.5)[0]                  # front axle at its peak
    assert yaw_moment_bound(z, P, 0.5, 0.0) == pytest.approx(0.0, abs=1e-6)
    z[R_.ALPHA_F] = 0.0
    assert yaw_moment_bound(z, P, 0.5, 0.5 * 9.81) == pytest.approx(0.0, abs=1e-6)


def test_the_lateral_grip_use_is_the_magic_formula_over_its_peak():
    """``lateral_use`` (compiled) against the Magic Formula written out: the larger of the
    axles' |F(α̂')| / D at μ̂, at most 1."""
    from fourws_mpc.core.friction_model import axle_loads

    rng = np.random.default_rng(11)
    c, e = P.tyre_shape_lateral, P.tyre_curvature_lateral
    for _ in range(200):
        mu = rng.uniform(0.2, 1.1)
        z = np.zeros(FM.N_STATE_FRICTION)
        z[R_.ALPHA_F], z[R_.ALPHA_R] = rng.uniform(-0.2, 0.2, 2)
        uses = []
        for alpha, k, fz in zip((z[R_.ALPHA_F], z[R_.ALPHA_R]), (2 * P.c_cf, 2 * P.c_cr),
                                axle_loads(P), strict=True):
            d = mu * fz
            bz = k / (c * d) * alpha
            uses.append(abs(d * math.sin(c * math.atan(bz - e * (bz - math.atan(bz))))) / d)
        assert lateral_use(z, P, mu) == pytest.approx(min(max(uses), 1.0), rel=1e-12)


def test_the_steer_window_is_the_peak_slip_around_the_kinematic_angle():
    vy, r = 0.3, 0.2
    lo, hi = steer_window(V, vy, r, P, 0.5)
    kin = np.array([(vy + P.a_m * r) / V, (vy - P.b_m * r) / V])
    np.testing.assert_allclose(0.5 * (lo + hi), kin, rtol=1e-12)
    np.testing.assert_allclose(0.5 * (hi - lo), peak_slips(P, 0.5), rtol=1e-12)


def test_peak_slips_are_the_plants_at_static_load():
    """The axle's peak slip u* C D/K equals the plant tyre's at static load (its own
    stiffness), within the load sensitivity of the plant's K_α (0.5 %)."""
    v = load_vehicle_params()
    fz = v.static_wheel_loads_n
    c_f, c_r = v.static_cornering_stiffness()
    u = peak_argument(C, E)
    plant = (u * C * 0.5 * fz[0] / c_f, u * C * 0.5 * fz[2] / c_r)
    np.testing.assert_allclose(peak_slips(P, 0.5), plant, rtol=5e-3)


def _ref():
    x = np.arange(-20.0, 400.0, 0.05)
    return Reference.from_arrays(x, np.zeros_like(x), np.zeros_like(x), np.zeros_like(x),
                                 np.full_like(x, V))


def test_the_controller_keeps_its_commands_inside_the_grip_envelope():
    """Far off the path on μ 0.3 with the front axle already past its peak: the front steer
    stays in the window around its kinematic angle (one increment of reach), and the yaw
    moment within the spare grip."""
    cfg = MpcConfig(prediction_model="single_track_friction", terminal_cost="lqr")
    ctrl = MpcController(cfg)
    ref = _ref()
    vy, r = -0.4, 0.25
    s = VehicleSample(0.0, -1.5, 0.0, V, vy, r, steer_front=0.1, ax=0.0, ay=2.5)
    res = None
    for k in range(30):
        res = ctrl.step(k * 0.01, VehicleSample(V * 0.01 * k, s.y, s.yaw, V, vy, r,
                                                steer_front=res.delta_front if res else 0.0,
                                                ay=2.5), ref, mu=0.3)
        kin = (vy + P.a_m * r) / V
        a_pf = peak_slips(ctrl.model.params, 0.3)[0]
        reach = math.radians(cfg.max_dsteer_front_deg)
        assert abs(res.delta_front - kin) <= a_pf + reach + 1e-9
        assert abs(res.yaw_moment) <= res.yaw_moment_bound + cfg.max_dyaw_moment_nm + 1e-9
        assert math.isfinite(res.mu_estimate) and res.mu_estimate == pytest.approx(0.3)
    assert not res.fallback


@pytest.mark.parametrize("ax,ay,seen_ax,seen_ay", [(0.5, 4.0, 0.5, 4.0),
                                                   (0.5, -150.0, 0.5, -1.2 * 9.81),
                                                   (30.0, 4.0, 1.2 * 9.81, 4.0),
                                                   (-150.0, 0.0, -1.2 * 9.81, 0.0)])
def test_the_prediction_takes_the_measured_accelerations_within_the_ceiling(ax, ay, seen_ax,
                                                                            seen_ay):
    """The controller hands the prediction the measured a_x, a_y for its loads, an absurd
    one (an IMU spike the input guard lets through) held to μ_ceiling g: the tyres' loads
    stay what a road can give (a 30 m/s² spike would lift a whole axle), and the step stays
    finite."""
    cfg = MpcConfig(prediction_model="single_track_friction", terminal_cost="lqr",
                    mu_ceiling=1.2)
    ctrl = MpcController(cfg)
    res = ctrl.step(0.0, VehicleSample(0.0, 0.1, 0.0, V, 0.0, 0.0, ax=ax, ay=ay), _ref(),
                    mu=0.8)
    assert ctrl.model.grip.ay_mps2 == pytest.approx(seen_ay, rel=1e-12)
    assert ctrl.model.grip.ax_mps2 == pytest.approx(seen_ax, rel=1e-12)
    assert all(math.isfinite(v) for v in (res.delta_front, res.delta_rear, res.yaw_moment))


def test_at_rest_loads_the_two_tyres_are_the_static_axle_and_a_lifted_wheel_drops_out():
    """a_x = a_y = 0: each axle is F(α'; 2 C_c, μ F_z,axle ε) with its slopes, at any slip
    and yaw moment (the Magic Formula is homogeneous in K and D together). A lateral
    acceleration that lifts the inner front wheel leaves the outer one alone, finite."""
    rng = np.random.default_rng(5)
    fz_f, fz_r = FM.axle_loads(P_CAR)
    for _ in range(5):
        z, u = _point(rng)
        mz = float(u[InputIdx.MZ])
        g = FM.Grip(0.7, 0.0, 0.0)
        eps, deps = FM.ellipse(mz, P_CAR, g)
        front, rear, _ = FM.axle_forces(z, mz, P_CAR, g)
        for got, alpha, c, fz in ((front, z[R_.ALPHA_F], P_CAR.c_cf, fz_f),
                                  (rear, z[R_.ALPHA_R], P_CAR.c_cr, fz_r)):
            f, df_da, df_dd = force(float(alpha), 2 * c, 0.7 * fz * eps, C, E)
            np.testing.assert_allclose(got, (f, df_da, df_dd * 0.7 * fz * deps),
                                       rtol=1e-12, atol=1e-9)
    v = load_vehicle_params()
    ay = 13.0                                           # beyond any road: the inner front lifts
    loads = wheel_loads(0.0, ay, LoadGeometry(
        v.mass_kg, v.cg_to_front_axle_m, v.cg_to_rear_axle_m, v.cg_height_m,
        v.track_width_front_m, v.track_width_rear_m, v.roll_stiffness_front_share,
        v.gravity_mps2))
    assert loads[0] == 0.0 < loads[1]
    z = np.zeros(FM.N_STATE_FRICTION)
    z[StateIdx.VX] = V
    z[R_.ALPHA_F] = 0.05
    (ff, dff, _), _, _ = FM.axle_forces(z, 0.0, P_CAR, FM.Grip(1.2, 0.0, ay))
    outer = _mf(0.05, float(cornering_stiffness(loads[1], v.tyre("front"))), 1.2 * loads[1])
    assert ff == pytest.approx(outer, rel=1e-9) and math.isfinite(dff)


def test_the_paper_models_report_the_mu_and_bound_they_used():
    cfg = MpcConfig()
    ctrl = MpcController(cfg)
    res = ctrl.step(0.0, VehicleSample(0.0, 0.1, 0.0, V, 0.0, 0.0), _ref(), mu=0.3)
    assert (res.mu_estimate, res.yaw_moment_bound) == (0.3, cfg.max_yaw_moment_nm)
    res = ctrl.step(0.01, VehicleSample(0.17, 0.1, 0.0, V, 0.0, 0.0), _ref())
    assert res.mu_estimate == cfg.mu_default
    assert ctrl._grip is None and cfg.u_max[InputIdx.MZ] == cfg.max_yaw_moment_nm


@pytest.mark.parametrize("c,e", [(1.01, 0.0), (1.3, 0.99), (1.99, -10.0), (1.3, -0.5)])
def test_the_peak_slip_is_the_magic_formulas_peak_anywhere_in_the_car_files_ranges(c, e):
    """C atan φ(u*) = π/2 at u* = B α_peak, also where the root lies far out (C near 1, E
    near 1: u* beyond 100); the peak slips follow it."""
    from fourws_common.magic_formula import peak_argument
    u = peak_argument(c, e)
    assert c * math.atan(u - e * (u - math.atan(u))) == pytest.approx(math.pi / 2, rel=1e-12)
    p = dataclasses.replace(P, tyre_shape_lateral=c, tyre_curvature_lateral=e)
    fz_f, _ = FM.axle_loads(p)
    assert peak_slips(p, 0.7)[0] == pytest.approx(u * c * 0.7 * fz_f / (2 * p.c_cf), rel=1e-12)
