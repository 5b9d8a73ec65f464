"""Magic Formula tyre with friction-ellipse combined slip: oracles, not snapshots.

Oracles: the numerical slope of the tyre curve at zero slip (cornering stiffness), the
pure-slip Magic Formula written out independently, the friction bound μ F_z, and agreement
of the numpy and plain-float implementations (and of the copy inlined in the vehicle model).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fourws_common.vehicle_info import read_vehicle_file
from fourws_common.wheels import Wheel
from fourws_sim.core import tyre
from fourws_sim.core.vehicle import _tyre_forces
from fourws_sim.core.vehicle_params import load_vehicle_params

P = load_vehicle_params()
FRONT, REAR = P.tyre("front"), P.tyre("rear")
SENSITIVE = load_vehicle_params(overrides={"tyre_friction_load_sensitivity": -0.1}).tyre("front")


def _mf(x, d, k, c, e):
    """Pure-slip Magic Formula, written out from the textbook form."""
    b = k / (c * d)
    return d * math.sin(c * math.atan(b * x - e * (b * x - math.atan(b * x))))


@pytest.mark.parametrize("mu", [0.3, 0.5, 1.0])
def test_cornering_stiffness_at_static_load_is_the_slope_of_the_curve(mu):
    loads = P.static_wheel_loads_n
    cf, cr = P.static_cornering_stiffness()
    h = 1e-6
    for fz, coeffs, expected in ((loads[Wheel.FL], FRONT, cf), (loads[Wheel.RL], REAR, cr)):
        _, fy_p = tyre.forces(0.0, h, fz, mu, coeffs)
        _, fy_m = tyre.forces(0.0, -h, fz, mu, coeffs)
        slope = float(fy_p - fy_m) / (2 * h)
        assert slope == pytest.approx(expected, rel=1e-6)


def test_static_cornering_stiffness_near_the_mpc_numbers_and_recorded_in_yaml():
    cf, cr = P.static_cornering_stiffness()
    assert cf == pytest.approx(28000.0, rel=0.01)
    assert cr == pytest.approx(30000.0, rel=0.01)
    raw = read_vehicle_file()
    assert raw["cornering_stiffness_front_static_n_per_rad"] == pytest.approx(cf, abs=1.0)
    assert raw["cornering_stiffness_rear_static_n_per_rad"] == pytest.approx(cr, abs=1.0)
    assert P.understeer_gradient() > 0.0  # mild understeer


@pytest.mark.parametrize("mu", [0.4, 1.0])
def test_longitudinal_slip_stiffness_is_the_slope_and_in_the_15_to_20_fz_range(mu):
    fz = 2000.0
    h = 1e-7
    fx_p, _ = tyre.forces(h, 0.0, fz, mu, FRONT)
    fx_m, _ = tyre.forces(-h, 0.0, fz, mu, FRONT)
    slope = float(fx_p - fx_m) / (2 * h)
    assert slope == pytest.approx(float(tyre.longitudinal_stiffness(fz, FRONT)), rel=1e-6)
    assert 15.0 <= slope / fz <= 20.0


@pytest.mark.parametrize("mu", [0.3, 0.8, 1.0])
@pytest.mark.parametrize("fz", [800.0, 2000.0, 3500.0])
def test_pure_slip_matches_the_magic_formula_and_peaks_at_mu_fz(mu, fz):
    ka = float(tyre.cornering_stiffness(fz, FRONT))
    kk = float(tyre.longitudinal_stiffness(fz, FRONT))
    alphas = np.linspace(-0.5, 0.5, 2001)
    kappas = np.linspace(-1.0, 1.0, 2001)
    _, fy = tyre.forces(np.zeros_like(alphas), alphas, fz, mu, FRONT)
    fx, _ = tyre.forces(kappas, np.zeros_like(kappas), fz, mu, FRONT)
    ref_y = [_mf(a, mu * fz, ka, FRONT.shape_lat, FRONT.curvature_lat) for a in alphas]
    ref_x = [_mf(k, mu * fz, kk, FRONT.shape_long, FRONT.curvature_long) for k in kappas]
    np.testing.assert_allclose(fy, ref_y, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(fx, ref_x, rtol=1e-9, atol=1e-9)
    assert np.max(fy) == pytest.approx(mu * fz, rel=1e-4)
    assert np.max(fx) == pytest.approx(mu * fz, rel=1e-4)


def test_cornering_stiffness_does_not_depend_on_mu_but_the_peak_slip_does():
    fz = 2000.0
    slopes, peaks = [], []
    for mu in (0.3, 0.6, 1.0):
        a = np.linspace(0.0, 0.4, 40001)
        _, fy = tyre.forces(np.zeros_like(a), a, fz, mu, FRONT)
        slopes.append(float(fy[1]) / a[1])
        peaks.append(a[np.argmax(fy)])
    assert max(slopes) == pytest.approx(min(slopes), rel=1e-6)
    assert peaks[0] < peaks[1] < peaks[2]
    assert peaks[2] == pytest.approx(peaks[0] / 0.3, rel=2e-3)


def test_friction_load_sensitivity_only_lowers_the_peak_of_heavy_tyres():
    a = np.linspace(0.0, 0.5, 5001)
    for fz, expected in ((1000.0, 1.0), (2000.0, 1.0), (4000.0, 0.9)):
        _, fy = tyre.forces(np.zeros_like(a), a, fz, 0.8, SENSITIVE)
        assert np.max(fy) == pytest.approx(0.8 * fz * expected, rel=1e-4)
        slope = float(fy[1]) / a[1]
        assert slope == pytest.approx(float(tyre.cornering_stiffness(fz, SENSITIVE)), rel=1e-5)


def test_load_sensitivity_is_degressive():
    fz = np.array([1000.0, 2000.0, 3000.0])
    k = tyre.cornering_stiffness(fz, FRONT)
    assert k[0] < k[1] < k[2]
    assert k[2] / fz[2] < k[1] / fz[1] < k[0] / fz[0]


finite = st.floats(allow_nan=False, allow_infinity=False)


@settings(max_examples=300, deadline=None)
@given(
    kappa=st.floats(-2.0, 2.0), alpha=st.floats(-1.2, 1.2), fz=st.floats(0.0, 6000.0),
    mu=st.floats(0.05, 1.5), sensitive=st.booleans(),
)
def test_combined_force_never_exceeds_mu_fz_and_implementations_agree(
    kappa, alpha, fz, mu, sensitive
):
    c = SENSITIVE if sensitive else FRONT
    fx, fy = tyre.forces(kappa, alpha, fz, mu, c)
    assert math.hypot(float(fx), float(fy)) <= mu * fz * (1 + 1e-9) + 1e-9
    k = c.scalar_constants(c.cornering_coeff)
    sx, sy = tyre.forces_scalar(kappa, alpha, fz, mu, k)
    assert sx == pytest.approx(float(fx), rel=1e-9, abs=1e-7)
    assert sy == pytest.approx(float(fy), rel=1e-9, abs=1e-7)


@settings(max_examples=200, deadline=None)
@given(
    vxw=st.floats(-30.0, 30.0), vyw=st.floats(-5.0, 5.0), omega_r=st.floats(-35.0, 35.0),
    fz=st.floats(0.0, 5000.0), mu=st.floats(0.05, 1.2),
)
def test_inlined_vehicle_tyre_equals_slips_plus_forces(vxw, vyw, omega_r, fz, mu):
    v_min = P.slip_speed_min_mps
    kappa, alpha = tyre.slips(np.array(vxw), np.array(vyw), np.array(omega_r), 1.0, v_min)
    fx, fy = tyre.forces(kappa, alpha, fz, mu, REAR)
    k = REAR.scalar_constants(REAR.cornering_coeff)
    den = max(abs(vxw), v_min)
    ix, iy = _tyre_forces(vxw, den, -math.atan(vyw / den), omega_r, fz, mu, k)
    assert ix == pytest.approx(float(fx), rel=1e-9, abs=1e-7)
    assert iy == pytest.approx(float(fy), rel=1e-9, abs=1e-7)


def test_small_combined_slip_keeps_both_linear_stiffnesses():
    fz, mu = 2000.0, 1.0
    kappa, alpha = 1e-5, 1e-5
    fx, fy = tyre.forces(kappa, alpha, fz, mu, FRONT)
    assert float(fx) == pytest.approx(float(tyre.longitudinal_stiffness(fz, FRONT)) * kappa,
                                      rel=1e-6)
    assert float(fy) == pytest.approx(float(tyre.cornering_stiffness(fz, FRONT)) * alpha,
                                      rel=1e-6)


def test_combined_slip_reduces_lateral_force_and_signs_follow_iso():
    fz, mu = 2000.0, 0.8
    _, fy_pure = tyre.forces(0.0, 0.05, fz, mu, FRONT)
    fx, fy = tyre.forces(0.08, 0.05, fz, mu, FRONT)
    assert 0 < float(fy) < float(fy_pure)
    assert float(fx) > 0
    # contact point sliding to the right (v_y < 0) in the wheel frame pushes the tyre left
    kappa, alpha = tyre.slips(np.array(20.0), np.array(-1.0), np.array(20.0), 1.0, 2.5)
    assert float(alpha) > 0 and float(kappa) == 0.0


def test_slips_stay_finite_at_standstill_and_zero_load_gives_zero_force():
    kappa, alpha = tyre.slips(np.zeros(4), np.zeros(4), np.array([0.0, 1.0, -1.0, 50.0]), 0.27,
                              2.5)
    assert np.all(np.isfinite(kappa)) and np.all(np.isfinite(alpha))
    fx, fy = tyre.forces(kappa, alpha, np.zeros(4), 1.0, FRONT)
    assert np.all(fx == 0) and np.all(fy == 0)


def test_peak_argument_solves_its_equation():
    for c, e in ((1.3, -1.0), (1.65, 0.0), (1.5, 0.5)):
        u = tyre.peak_argument(c, e)
        assert c * math.atan(u - e * (u - math.atan(u))) == pytest.approx(math.pi / 2, abs=1e-12)
    with pytest.raises(ValueError, match="shape factor"):
        tyre.peak_argument(2.5, 0.0)
    with pytest.raises(ValueError, match="curvature factor"):
        tyre.peak_argument(1.3, 1.0)
