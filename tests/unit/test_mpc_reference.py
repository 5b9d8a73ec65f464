"""Reference path: nearest point and path-frame errors on a straight line and a circle."""

import math

import numpy as np
import pytest

from fourws_mpc.core.reference import Reference, wrap_angle


def _line(theta=0.3, n=2001, length=200.0):
    s = np.linspace(0, length, n)
    return Reference.from_arrays(s * math.cos(theta), s * math.sin(theta), np.full(n, theta),
                                 np.zeros(n), np.full(n, 10.0))


def _circle(R=40.0, n=4001, turns=1.5):
    a = np.linspace(0, 2 * math.pi * turns, n)
    x, y = R * np.sin(a), R * (1 - np.cos(a))        # start at origin heading +X, turning left
    return Reference.from_arrays(x, y, a, np.full(n, 1 / R), np.full(n, 12.0))


def test_wrap_angle_range():
    assert wrap_angle(math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_angle(np.array([0.1 + 4 * math.pi]))[0] == pytest.approx(0.1)


@pytest.mark.parametrize("offset", [-1.3, 0.0, 0.7])
def test_straight_line_errors(offset):
    th = 0.3
    ref = _line(th)
    s0 = 57.31
    px = s0 * math.cos(th) - offset * math.sin(th)
    py = s0 * math.sin(th) + offset * math.cos(th)
    e = ref.errors(px, py, th + 0.1 + 2 * math.pi)
    assert e.lateral_error == pytest.approx(offset, abs=1e-9)
    assert e.heading_error == pytest.approx(0.1, abs=1e-12)
    assert e.near.s == pytest.approx(s0, abs=1e-9)


@pytest.mark.parametrize("radial", [-2.0, 0.0, 1.5])
def test_circle_errors_against_geometry(radial):
    R = 40.0
    ref = _circle(R, turns=0.9)
    ang = 1.234
    centre = np.array([0.0, R])
    # a point at radius R − radial: inside the left turn = left of the path = positive e_Y
    p = centre + (R - radial) * np.array([math.sin(ang), -math.cos(ang)])
    yaw = ang + 0.05
    e = ref.errors(p[0], p[1], yaw)
    assert e.lateral_error == pytest.approx(radial, abs=2e-3)   # chord sag ≈ R (Δa)²/8
    assert e.heading_error == pytest.approx(0.05, abs=1e-3)
    assert e.near.s == pytest.approx(R * ang, abs=1e-2)


def test_window_search_follows_and_recovers():
    ref = _circle(40.0, turns=1.5)
    R = 40.0
    hint = 0
    for ang in np.linspace(0.1, 2 * math.pi + 1.0, 200):  # second lap overlaps the first
        p = (R * math.sin(ang), R * (1 - math.cos(ang)))
        near = ref.nearest(*p, hint)
        hint = near.index
        assert near.s == pytest.approx(R * ang, abs=0.05)
    # a point outside the window falls back to a global search
    line = _line(0.0, n=2001, length=200.0)
    assert line.nearest(10.0, 0.3, hint=1500).s == pytest.approx(10.0, abs=1e-9)


def test_horizon_on_a_circle_in_path_frame():
    R, v, dt, n_p = 40.0, 12.0, 0.01, 30
    ref = _circle(R)
    near = ref.nearest(R * math.sin(0.8), R * (1 - math.cos(0.8)))
    phi_ref, y_ref = ref.horizon(near, v, dt, n_p, vehicle_yaw=0.8)
    ds = v * dt * np.arange(1, n_p + 1)
    np.testing.assert_allclose(phi_ref, ds / R, atol=1e-6)
    np.testing.assert_allclose(y_ref, R * (1 - np.cos(ds / R)), atol=2e-4)


def test_horizon_global_frame_unwraps_to_vehicle_yaw():
    ref = _line(0.2)
    near = ref.nearest(10.0, 2.0)
    phi_ref, y_ref = ref.horizon(near, 10.0, 0.01, 5, vehicle_yaw=0.2 + 4 * math.pi,
                                 frame="global")
    np.testing.assert_allclose(phi_ref, 0.2 + 4 * math.pi)
    ds = 0.1 * np.arange(1, 6)
    np.testing.assert_allclose(y_ref, (near.s + ds) * math.sin(0.2), atol=1e-9)


def test_extrapolates_straight_beyond_the_end():
    ref = _line(0.0, n=101, length=10.0)
    near = ref.nearest(12.0, 0.5)
    assert near.s == pytest.approx(12.0)
    assert near.lateral_error == pytest.approx(0.5)
    x, y, yaw, k, v = ref.sample(np.array([15.0]))
    assert (x[0], y[0], k[0]) == pytest.approx((15.0, 0.0, 0.0))


def test_bad_arrays_raise_naming_them():
    with pytest.raises(ValueError, match="speed"):
        Reference.from_arrays([0, 1], [0, 0], [0, 0], [0, 0], [1.0])
    with pytest.raises(ValueError, match="y"):
        Reference.from_arrays([0, 1], [0, float("nan")], [0, 0], [0, 0], [1, 1])
    with pytest.raises(ValueError, match="distinct"):
        Reference.from_arrays([0, 0], [0, 0], [0, 0], [0, 0], [1, 1])


def _pose_oracle(ref, sq):
    """x, y, yaw at ``sq`` written out with numpy: interpolation, and beyond each end the end
    heading continued straight."""
    s = ref.s
    x, y, yaw = (np.interp(sq, s, a) for a in (ref.x, ref.y, ref.yaw))
    for out, end in ((sq > s[-1], -1), (sq < s[0], 0)):
        d = sq - s[end]
        x = np.where(out, ref.x[end] + d * math.cos(ref.yaw[end]), x)
        y = np.where(out, ref.y[end] + d * math.sin(ref.yaw[end]), y)
    return x, y, yaw


@pytest.mark.parametrize("frame", ["path", "global"])
@pytest.mark.parametrize("behind", [-30.0, -190.0, 2.0])   # inside; off the end; before start
def test_the_compiled_horizon_is_the_sampled_path(frame, behind):
    """``horizon`` (compiled) against the path sampled with numpy, on a circle's arc whose
    ends are curved: inside, running off the end, and from a car behind the start (the first
    points lie before it)."""
    ref = _circle(R=40.0, n=801, turns=0.75)
    s0 = -behind if behind < 0 else 0.0
    x0, y0, _, _, _ = ref.sample(np.array([s0]))
    if behind > 0:                                    # the start heads along +X
        x0 = x0 - behind
    near = ref.nearest(float(x0[0]), float(y0[0]) - 0.2)
    v, dt, n_p = 15.0, 0.01, 40
    sq = near.s + v * dt * np.arange(1, n_p + 1)
    assert (sq.min() < 0.0) == (behind > 0) and (sq.max() > ref.length) == (behind < -100)
    phi_ref, y_ref = ref.horizon(near, v, dt, n_p, vehicle_yaw=near.yaw + 2 * math.pi,
                                 frame=frame)
    x, y, yaw = _pose_oracle(ref, sq)
    if frame == "path":
        c, s = math.cos(near.yaw), math.sin(near.yaw)
        np.testing.assert_allclose(phi_ref, yaw - near.yaw, rtol=0, atol=1e-15)
        np.testing.assert_allclose(y_ref, -s * (x - near.x) + c * (y - near.y), rtol=0,
                                   atol=1e-12)
    else:
        np.testing.assert_allclose(phi_ref, yaw + 2 * math.pi, rtol=0, atol=1e-12)
        np.testing.assert_allclose(y_ref, y, rtol=0, atol=1e-12)


def test_every_array_of_a_reference_is_read_only():
    ref = _line()
    for a in (ref.x, ref.y, ref.yaw, ref.curvature, ref.speed, ref.s):
        with pytest.raises(ValueError):
            a[0] = 1.0
