"""Reference paths: analytic heading/curvature against finite differences, geometry, helpers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fourws_sim.core import paths

SPEED = 10.0


def _fd_heading_curvature(x, y):
    yp = np.gradient(y, x, edge_order=2)
    ypp = np.gradient(yp, x, edge_order=2)
    return np.arctan(yp), ypp / (1 + yp * yp) ** 1.5


@pytest.mark.parametrize("stretch", [1.0, 60 / 36, 2.5])
def test_tanh_dlc_heading_and_curvature_match_finite_differences_of_y(stretch):
    p = paths.tanh_dlc(SPEED, stretch=stretch, spacing_m=0.01)
    yaw_fd, kappa_fd = _fd_heading_curvature(p.x, p.y)
    inner = slice(5, -5)
    np.testing.assert_allclose(p.yaw[inner], yaw_fd[inner], atol=1e-7)
    np.testing.assert_allclose(p.curvature[inner], kappa_fd[inner],
                               atol=1e-5 * np.max(np.abs(p.curvature)))


def test_tanh_dlc_values_of_the_notes():
    y0, _, _ = paths.tanh_dlc_geometry(np.array([0.0]))
    assert y0[0] == pytest.approx(0.002, abs=2e-4)
    y_end, yp_end, _ = paths.tanh_dlc_geometry(np.array([400.0]))
    assert y_end[0] == pytest.approx(4.05 - 5.7, abs=1e-6)
    p = paths.tanh_dlc(SPEED)
    assert np.max(np.abs(p.curvature)) == pytest.approx(0.0271, abs=5e-4)
    assert paths.peak_lateral_accel_demand(p) == pytest.approx(2.7, abs=0.1)
    assert p.y[-1] == pytest.approx(-1.65, abs=0.03)
    assert abs(p.yaw[0]) < 1e-3 and abs(p.yaw[-1]) < 1e-3  # straight at both ends


def test_stretch_divides_the_peak_curvature_by_stretch_squared():
    x = np.linspace(-50, 1000, 200001)
    base = paths.tanh_dlc_geometry(x)
    peak_kappa0 = np.max(np.abs(paths.tanh_dlc(SPEED, spacing_m=0.01).curvature))
    for s in (60 / 36, 2.5):
        stretched = paths.tanh_dlc_geometry(x * s, stretch=s)
        np.testing.assert_allclose(stretched[0], base[0], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(stretched[2], base[2] / s**2, rtol=1e-9, atol=1e-15)
        peak = np.max(np.abs(paths.tanh_dlc(SPEED, stretch=s, spacing_m=0.01).curvature))
        # κ = Y''/(1+Y'²)^1.5: the slope term makes it slightly more than 1/s² of the original
        assert peak * s**2 == pytest.approx(peak_kappa0, rel=0.05)


@pytest.mark.parametrize("name", ["tanh_dlc", "iso3888", "circle", "sine", "straight"])
def test_sampling_is_fine_and_arrays_are_consistent(name):
    p = paths.path_from_mapping({"type": name}, SPEED)
    ds = np.diff(p.s)
    assert np.all(ds > 0) and np.max(ds) <= 0.1
    chord = np.hypot(np.diff(p.x), np.diff(p.y))
    np.testing.assert_allclose(ds, chord, rtol=1e-3)
    assert p.x[0] <= -19.9  # lead-in from X = −20 m
    assert abs(p.curvature[0]) < 1e-4
    assert np.all(p.speed == SPEED)
    with pytest.raises(ValueError):
        p.x[0] = 1.0  # read-only arrays


def test_iso3888_centre_line_keeps_the_car_inside_the_cones():
    w = 1.5
    p = paths.iso3888(SPEED, vehicle_width_m=w, spacing_m=0.01)
    for lane, (x0, x1, yc, width) in enumerate(paths.iso3888_lanes(w)):
        sel = (p.x >= x0) & (p.x <= x1)
        assert np.all(np.abs(p.y[sel] - yc) + w / 2 <= width / 2 + 1e-9), (x0, x1)
        if lane < 2:  # the entry and side lanes bind: the steps are as gentle as they allow
            assert np.max(np.abs(p.y[sel] - yc)) + w / 2 > width / 2 - 1e-3
    yaw_fd, kappa_fd = _fd_heading_curvature(p.x, p.y)
    np.testing.assert_allclose(p.yaw[5:-5], yaw_fd[5:-5], atol=1e-6)
    np.testing.assert_allclose(p.curvature[5:-5], kappa_fd[5:-5], atol=1e-5)
    assert np.max(p.y) == pytest.approx(3.5, abs=0.15)
    assert abs(p.y[-1]) < 1e-3


def test_circle_has_constant_radius_after_the_clothoid():
    radius = 40.0
    p = paths.circle(SPEED, radius_m=radius, lead_in_m=20.0, transition_m=20.0, arc_deg=270.0)
    arc = p.s >= 40.0
    np.testing.assert_allclose(p.curvature[arc], 1.0 / radius)
    i = np.argmax(arc)
    cx = p.x[i] - radius * math.sin(p.yaw[i])
    cy = p.y[i] + radius * math.cos(p.yaw[i])
    dist = np.hypot(p.x[arc] - cx, p.y[arc] - cy)
    assert np.max(np.abs(dist - radius)) < 0.01
    assert p.yaw[-1] == pytest.approx(math.radians(270.0) + 20.0 / (2 * radius), rel=1e-9)
    right = paths.circle(SPEED, radius_m=radius, direction="right")
    assert np.all(right.curvature <= 0) and right.y[-1] < 0


def test_sine_derivatives_and_envelope():
    p = paths.sine(SPEED, amplitude_m=1.0, wavelength_m=60.0, periods=2.0, x0_m=0.0,
                   spacing_m=0.01)
    yaw_fd, kappa_fd = _fd_heading_curvature(p.x, p.y)
    np.testing.assert_allclose(p.yaw[5:-5], yaw_fd[5:-5], atol=1e-6)
    np.testing.assert_allclose(p.curvature[5:-5], kappa_fd[5:-5], atol=1e-5)
    assert np.max(np.abs(p.y)) <= 1.0 + 1e-12
    assert np.all(p.y[p.x <= 0.0] == 0.0) and np.all(p.y[p.x >= 120.0] == 0.0)


def test_speed_profile_and_peak_demand():
    p = paths.straight(SPEED, speed_profile_kmh=[[0.0, 72.0], [50.0, 36.0]])
    assert p.speed[0] == pytest.approx(20.0) and p.speed[-1] == pytest.approx(10.0)
    assert np.interp(25.0, p.x, p.speed) == pytest.approx(15.0)
    assert paths.peak_lateral_accel_demand(p) == 0.0
    c = paths.circle(SPEED, radius_m=50.0)
    assert paths.peak_lateral_accel_demand(c) == pytest.approx(SPEED**2 / 50.0)
    assert paths.peak_lateral_accel_demand(c, 20.0) == pytest.approx(400.0 / 50.0)


def test_lateral_error_is_signed_left_positive():
    p = paths.tanh_dlc(SPEED, stretch=60 / 36)
    for i in (1000, 1500, 2500, 3500):
        nx, ny = -math.sin(p.yaw[i]), math.cos(p.yaw[i])
        assert paths.lateral_error(p, p.x[i], p.y[i]) == pytest.approx(0.0, abs=1e-9)
        assert paths.lateral_error(p, p.x[i] + 0.5 * nx, p.y[i] + 0.5 * ny) == pytest.approx(
            0.5, abs=1e-3)
        assert paths.lateral_error(p, p.x[i] - 0.3 * nx, p.y[i] - 0.3 * ny) == pytest.approx(
            -0.3, abs=1e-3)
    # between samples: the projection is exact on the tangent
    x = 0.5 * (p.x[2000] + p.x[2001])
    y, _, _ = paths.tanh_dlc_geometry(np.array([x]), stretch=60 / 36)
    assert paths.lateral_error(p, x, float(y[0])) == pytest.approx(0.0, abs=1e-5)


def test_bad_path_mappings_raise():
    with pytest.raises(ValueError, match="path.type"):
        paths.path_from_mapping({"type": "spiral"}, SPEED)
    with pytest.raises(ValueError, match="bogus"):
        paths.path_from_mapping({"type": "circle", "bogus": 1.0}, SPEED)
    with pytest.raises(ValueError, match="radius_m"):
        paths.path_from_mapping({"type": "circle", "radius_m": "big"}, SPEED)
    with pytest.raises(ValueError, match="circle"):
        paths.path_from_mapping({"type": "circle", "radius_m": -1.0}, SPEED)
    auto = paths.path_from_mapping({"type": "tanh_dlc", "stretch": "auto"}, 25.0)
    explicit = paths.tanh_dlc(25.0, stretch=2.5)
    np.testing.assert_array_equal(auto.y, explicit.y)
