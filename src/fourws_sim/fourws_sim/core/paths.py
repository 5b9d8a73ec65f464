"""Builds reference paths: arrays x, y, yaw, curvature, s, speed sampled every ≤ 0.05 m.

The scenarios' path types (docs/plant.md, "Reference paths"). Every path starts with a
straight (or asymptotically straight) lead-in at X = ``x_start_m`` (default −20 m) and ends
with a lead-out, so the car starts and ends on straight road. The heading ``yaw`` is
continuous (unwrapped), in rad, CCW from X; curvature in 1/m, positive to the left; ``s`` the
arc length from the first sample.

1. ``tanh_dlc``: the "double shifting line" of the literature::

       z_i = shape/dx_i (X/σ − Xs_i) − shape/2,      k_i = shape/dx_i
       Y   = dy1/2 (1 + tanh z1) − dy2/2 (1 + tanh z2)
       Y'  = [dy1/2 k1 sech² z1 − dy2/2 k2 sech² z2] / σ
       Y'' = [−dy1 k1² tanh z1 sech² z1 + dy2 k2² tanh z2 sech² z2] / σ²
       ψ = atan(Y'),   κ = Y'' / (1 + Y'²)^{3/2}

   with σ the stretch along X (σ = v/(10 m/s) keeps the 10 m/s lateral-acceleration demand
   at any speed, since κ scales as 1/σ²). Heading and curvature come from the analytic
   derivatives, never from the Y column. The path ends at Y = dy1 − dy2 = −1.65 m.

2. ``iso3888``: a smooth centre line through the ISO 3888-1 double-lane-change course.
   Sections (length, lane width for a car of width w): 1 entry lane 15 m, 1.1w + 0.25;
   2 transition 30 m; 3 side lane 25 m, 1.2w + 0.25, its centre ``lane_offset_m`` = 3.5 m
   to the left; 4 transition 25 m; 5 and 6 exit lane 15 + 15 m, 1.3w + 0.25 (back on
   Y = 0). Section 1 starts at X = 0. The centre line is two tanh steps of height h = 3.5 m
   centred in sections 2 and 4, Y = h/2 (tanh k1 (X − 30) − tanh k2 (X − 82.5)), each with
   the smallest steepness that keeps the car's body inside the cones of the lanes on both
   sides when the centre line is followed exactly: |Y − Y_lane| ≤ (lane width − w)/2 at the
   lane ends next to the step (about h/2 (1 − tanh(k d)) at a distance d from the step
   centre; solved numerically with the other step's tail included). The transitions begin
   inside the lanes (confined to the gaps they would demand about 13 m/s² at 80 km/h).

3. ``circle``: lead-in straight, clothoid (curvature linear in s) over ``transition_m``,
   then an arc of radius R over ``arc_deg`` (to the left, or right with ``direction``),
   positions integrated from the heading.

4. ``sine``: Y = A e(X) sin(2π (X − x0)/λ) over ``periods`` wavelengths, e(X) a quintic
   smooth-step envelope over ``ramp_m`` at both ends (curvature continuous at the joins),
   analytic derivatives.

5. ``straight``: Y = 0.

6. ``iso3888_2``: a smooth centre line through the ISO 3888-2 obstacle-avoidance course
   (../shared/limit-handling-notes.md): 1 entry lane 12 m, 1.1w + 0.25; 2 gap 13.5 m;
   3 side lane 11 m, w + 1, its near edge 1 m beyond the entry lane's left edge; 4 gap
   12.5 m; 5 exit lane 12 m, max(1.3w + 0.25, 3), its right edge on the entry lane's right
   edge. One tanh step per gap, centred in it, each as gentle as the cones allow the body
   (:func:`cone_steepness`), with ``cone_margin_m`` to spare at the lane ends.

``speed`` is the scenario speed, or a piecewise-linear profile in X
(``speed_profile_kmh: [[x_m, v_kmh], ...]``).
"""

from __future__ import annotations

import dataclasses
import inspect
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from itertools import pairwise
from typing import Any

import numpy as np

from fourws_common.path_lookup import nearest_sample

DEFAULT_SPACING_M = 0.05
DEFAULT_X_START_M = -20.0
LEAD_OUT_M = 60.0

ISO3888_SECTIONS_M = (15.0, 30.0, 25.0, 25.0, 15.0, 15.0)

TANH_DLC_DEFAULTS = {
    "shape": 2.4, "dx1_m": 25.0, "dx2_m": 21.95, "dy1_m": 4.05, "dy2_m": 5.7,
    "xs1_m": 27.19, "xs2_m": 56.46,
}


#: the body width of a course's lanes when a scenario names none (m)
VEHICLE_WIDTH_M = 1.5

@dataclass(frozen=True, eq=False)
class ReferencePath:
    """A sampled reference path; every array has shape (N,)."""

    name: str
    x: np.ndarray  # m
    y: np.ndarray  # m
    yaw: np.ndarray  # rad, continuous
    curvature: np.ndarray  # 1/m
    s: np.ndarray  # m
    speed: np.ndarray  # m/s
    #: the cone lanes of a test course, (x_from, x_to, y_centre, width) in m; empty if none
    lanes: tuple = ()
    #: the body width the lanes are set out for and checked against (m)
    vehicle_width_m: float = VEHICLE_WIDTH_M

    def __post_init__(self) -> None:
        n = len(self.x)
        for name in ("y", "yaw", "curvature", "s", "speed"):
            arr = getattr(self, name)
            if arr.shape != (n,):
                raise ValueError(f"ReferencePath.{name}: shape {arr.shape}, expected ({n},)")
            arr.setflags(write=False)
        self.x.setflags(write=False)
        if n < 2 or not np.all(np.isfinite(self.x)) or not np.all(np.isfinite(self.y)):
            raise ValueError("ReferencePath: needs at least two finite points")

    def __len__(self) -> int:
        return len(self.x)


# --- geometry ---------------------------------------------------------------------------


def tanh_dlc_geometry(
    x: np.ndarray,
    stretch: float = 1.0,
    shape: float = 2.4,
    dx1_m: float = 25.0,
    dx2_m: float = 21.95,
    dy1_m: float = 4.05,
    dy2_m: float = 5.7,
    xs1_m: float = 27.19,
    xs2_m: float = 56.46,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Y, dY/dX, d²Y/dX²) of the tanh double lane change at X (m), analytically."""
    xn = np.asarray(x, dtype=float) / stretch
    k1, k2 = shape / dx1_m, shape / dx2_m
    t1 = np.tanh(k1 * (xn - xs1_m) - shape / 2.0)
    t2 = np.tanh(k2 * (xn - xs2_m) - shape / 2.0)
    s1, s2 = 1.0 - t1 * t1, 1.0 - t2 * t2
    y = dy1_m / 2.0 * (1.0 + t1) - dy2_m / 2.0 * (1.0 + t2)
    yp = (dy1_m / 2.0 * k1 * s1 - dy2_m / 2.0 * k2 * s2) / stretch
    ypp = (-dy1_m * k1 * k1 * t1 * s1 + dy2_m * k2 * k2 * t2 * s2) / (stretch * stretch)
    return y, yp, ypp


def tanh_dlc_settled_x(stretch: float = 1.0, **geometry: float) -> float:
    """X (m) where the second tanh has reached tanh z2 = 0.99: Y is then within
    dy2/2 · 0.01 ≈ 3 cm of its final value dy1 − dy2 = −1.65 m."""
    g = {**TANH_DLC_DEFAULTS, **geometry}
    z2 = math.atanh(0.99)
    return stretch * (g["xs2_m"] + (z2 + g["shape"] / 2.0) * g["dx2_m"] / g["shape"])


def iso3888_steepness(
    vehicle_width_m: float = VEHICLE_WIDTH_M, lane_offset_m: float = 3.5, cone_margin_m: float = 0.0
) -> tuple[float, float, float, float]:
    """(X_c1, k1, X_c2, k2) of the two tanh steps of the ISO 3888-1 centre line (m, 1/m):
    each k the smallest that keeps the car's body ``cone_margin_m`` inside the cones at the
    four lane ends next to its step, the other step's tail included (a few fixed-point
    rounds)."""
    lengths = ISO3888_SECTIONS_M
    starts = np.concatenate(([0.0], np.cumsum(lengths)))
    w, h = vehicle_width_m, lane_offset_m
    lanes = iso3888_lanes(vehicle_width_m, lane_offset_m)
    xc1 = float(starts[1] + lengths[1] / 2.0)
    xc2 = float(starts[3] + lengths[3] / 2.0)
    # (X of a lane end, lane centre Y, half the free width) next to each step
    m = cone_margin_m
    checks = {
        1: [(lanes[0][1], lanes[0][2], (lanes[0][3] - w) / 2.0 - m),
            (lanes[1][0], lanes[1][2], (lanes[1][3] - w) / 2.0 - m)],
        2: [(lanes[1][1], lanes[1][2], (lanes[1][3] - w) / 2.0 - m),
            (lanes[2][0], lanes[2][2], (lanes[2][3] - w) / 2.0 - m)],
    }
    if min(m for c in checks.values() for _, _, m in c) <= 0.0:
        raise ValueError(f"path.vehicle_width_m: {w} m does not fit the ISO 3888-1 lanes")

    def y_at(x: float, k1: float, k2: float) -> float:
        return h / 2.0 * (math.tanh(k1 * (x - xc1)) - math.tanh(k2 * (x - xc2)))

    def fits(i: int, k: list[float]) -> bool:
        return max(abs(y_at(x, k[0], k[1]) - yc) - m for x, yc, m in checks[i + 1]) <= 0.0

    k1, k2 = fit_steepness(fits, 2)
    return xc1, k1, xc2, k2


def iso3888_lanes(vehicle_width_m: float = VEHICLE_WIDTH_M, lane_offset_m: float = 3.5
                  ) -> list[tuple]:
    """[(x_from, x_to, y_centre, width)] of the cone lanes of ISO 3888-1 (sections 1, 3, 5,
    6), m."""
    lengths = ISO3888_SECTIONS_M
    starts = np.concatenate(([0.0], np.cumsum(lengths)))
    w = vehicle_width_m
    return [
        (starts[0], starts[1], 0.0, 1.1 * w + 0.25),
        (starts[2], starts[3], lane_offset_m, 1.2 * w + 0.25),
        (starts[4], starts[6], 0.0, 1.3 * w + 0.25),
    ]


ISO3888_2_SECTIONS_M = (12.0, 13.5, 11.0, 12.5, 12.0)


def iso3888_2_lanes(vehicle_width_m: float = VEHICLE_WIDTH_M) -> list[tuple]:
    """[(x_from, x_to, y_centre, width)] of the three cone lanes of ISO 3888-2, m."""
    w = vehicle_width_m
    starts = np.concatenate(([0.0], np.cumsum(ISO3888_2_SECTIONS_M)))
    entry, side, exit_ = 1.1 * w + 0.25, w + 1.0, max(1.3 * w + 0.25, 3.0)
    side_y = entry / 2.0 + 1.0 + side / 2.0
    exit_y = -entry / 2.0 + exit_ / 2.0
    return [(starts[0], starts[1], 0.0, entry), (starts[2], starts[3], side_y, side),
            (starts[4], starts[5], exit_y, exit_)]


def _steps_y(x: float, y0: float, steps: Sequence[tuple[float, float, float]]) -> float:
    return y0 + sum(h / 2.0 * (1.0 + math.tanh(k * (x - xc))) for xc, h, k in steps)


def cone_steepness(lanes: Sequence[tuple], vehicle_width_m: float, cone_margin_m: float = 0.0
                   ) -> list[tuple[float, float, float]]:
    """[(X_c, height, k)] of the tanh steps between consecutive lanes: centred in each gap,
    each k the smallest that keeps the body ``cone_margin_m`` within the cones at the two
    lane ends next to its step, the other steps' tails included (a few fixed-point
    rounds)."""
    w = vehicle_width_m
    free = [(ln[3] - w) / 2.0 - cone_margin_m for ln in lanes]
    if min(free) <= 0.0:
        raise ValueError(f"path.vehicle_width_m: {w} m does not fit the course's lanes")
    steps = [[0.5 * (a[1] + b[0]), b[2] - a[2], 1.0] for a, b in pairwise(lanes)]
    y0 = lanes[0][2]
    checks = [[(a[1], a[2], fa), (b[0], b[2], fb)]
              for (a, b), (fa, fb) in zip(pairwise(lanes), pairwise(free), strict=True)]
    def fits(i: int, k: list[float]) -> bool:
        for st, ki in zip(steps, k, strict=True):
            st[2] = ki
        return all(abs(_steps_y(x, y0, steps) - yc) <= m for x, yc, m in checks[i])

    for st, ki in zip(steps, fit_steepness(fits, len(steps)), strict=True):
        st[2] = ki
    return [tuple(st) for st in steps]


#: :func:`fit_steepness`: fixed-point rounds over the steps, bisection steps per step, and the
#: bracket of k (1/m)
STEEPNESS_ROUNDS, STEEPNESS_BISECTIONS, STEEPNESS_BRACKET = 6, 80, (1e-3, 5.0)


def fit_steepness(fits: Callable[[int, list[float]], bool], n_steps: int) -> list[float]:
    """The smallest steepness k_i of each of ``n_steps`` tanh steps for which ``fits(i, k)``
    holds (the body inside the cones next to step i, the other steps at their current k):
    bisection on each step in turn, repeated for a few fixed-point rounds, from k = 1."""
    k = [1.0] * n_steps
    for _ in range(STEEPNESS_ROUNDS):
        for i in range(n_steps):
            lo, hi = STEEPNESS_BRACKET
            for _ in range(STEEPNESS_BISECTIONS):
                k[i] = mid = 0.5 * (lo + hi)
                lo, hi = (lo, mid) if fits(i, k) else (mid, hi)
            k[i] = hi
    return k


def iso3888_2(
    speed_mps: float,
    vehicle_width_m: float = VEHICLE_WIDTH_M,
    cone_margin_m: float = 0.0,
    x_start_m: float = DEFAULT_X_START_M,
    x_end_m: float | None = None,
    spacing_m: float = DEFAULT_SPACING_M,
    speed_profile_kmh: Sequence | None = None,
) -> ReferencePath:
    """Smooth centre line of the ISO 3888-2 course (section 1 starts at X = 0)."""
    lanes = iso3888_2_lanes(vehicle_width_m)
    steps = cone_steepness(lanes, vehicle_width_m, cone_margin_m)
    if x_end_m is None:
        x_end_m = sum(ISO3888_2_SECTIONS_M) + LEAD_OUT_M
    x = _x_grid(x_start_m, x_end_m, spacing_m)
    y = np.full_like(x, lanes[0][2])
    yp = np.zeros_like(x)
    ypp = np.zeros_like(x)
    for xc, h, k in steps:
        t = np.tanh(k * (x - xc))
        sech2 = 1.0 - t * t
        y += h / 2.0 * (1.0 + t)
        yp += h / 2.0 * k * sech2
        ypp += -h * k * k * t * sech2
    path = _graph_path("iso3888_2", x, y, yp, ypp,
                       _speed_array(x, speed_mps, speed_profile_kmh))
    return dataclasses.replace(path, lanes=tuple(lanes), vehicle_width_m=vehicle_width_m)


def _smoothstep(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    u = np.clip(u, 0.0, 1.0)
    return (
        u**3 * (10.0 - 15.0 * u + 6.0 * u * u),
        30.0 * u * u * (1.0 - u) ** 2,
        60.0 * u * (1.0 - u) * (1.0 - 2.0 * u),
    )


def sine_geometry(
    x: np.ndarray, amplitude_m: float, wavelength_m: float, periods: float, x0_m: float,
    ramp_m: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Y, Y', Y'') of the enveloped sine at X (m)."""
    x = np.asarray(x, dtype=float)
    x1 = x0_m + periods * wavelength_m
    a_s, a_d, a_dd = _smoothstep((x - x0_m) / ramp_m)
    b_s, b_d, b_dd = _smoothstep((x1 - x) / ramp_m)
    e = a_s * b_s
    ep = (a_d * b_s - a_s * b_d) / ramp_m
    epp = (a_dd * b_s - 2.0 * a_d * b_d + a_s * b_dd) / (ramp_m * ramp_m)
    k = 2.0 * math.pi / wavelength_m
    sn, cs = np.sin(k * (x - x0_m)), np.cos(k * (x - x0_m))
    y = amplitude_m * e * sn
    yp = amplitude_m * (ep * sn + e * k * cs)
    ypp = amplitude_m * (epp * sn + 2.0 * ep * k * cs - e * k * k * sn)
    return y, yp, ypp


# --- path builders ----------------------------------------------------------------------


def _x_grid(x_start: float, x_end: float, spacing: float) -> np.ndarray:
    if not x_end > x_start:
        raise ValueError(f"path: x_end_m ({x_end}) must be greater than x_start_m ({x_start})")
    n = int(math.ceil((x_end - x_start) / spacing)) + 1
    return np.linspace(x_start, x_end, n)


def _speed_array(x: np.ndarray, speed_mps: float, profile: Sequence | None) -> np.ndarray:
    if profile is None:
        return np.full(x.shape, float(speed_mps))
    pts = np.asarray(profile, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 1 or np.any(np.diff(pts[:, 0]) <= 0):
        raise ValueError("path.speed_profile_kmh: expected [[x_m, v_kmh], ...] with x increasing")
    if np.any(pts[:, 1] < 0) or not np.all(np.isfinite(pts)):
        raise ValueError("path.speed_profile_kmh: speeds must be finite and >= 0")
    return np.interp(x, pts[:, 0], pts[:, 1] / 3.6)


def _graph_path(
    name: str, x: np.ndarray, y: np.ndarray, yp: np.ndarray, ypp: np.ndarray, speed: np.ndarray
) -> ReferencePath:
    slope = np.sqrt(1.0 + yp * yp)
    s = np.concatenate(([0.0], np.cumsum(0.5 * (slope[1:] + slope[:-1]) * np.diff(x))))
    return ReferencePath(
        name=name, x=x, y=y, yaw=np.arctan(yp), curvature=ypp / slope**3, s=s, speed=speed
    )


def tanh_dlc(
    speed_mps: float,
    stretch: float = 1.0,
    x_start_m: float = DEFAULT_X_START_M,
    x_end_m: float | None = None,
    spacing_m: float = DEFAULT_SPACING_M,
    speed_profile_kmh: Sequence | None = None,
    **geometry: float,
) -> ReferencePath:
    """The tanh double lane change, stretched by ``stretch`` along X."""
    g = {**TANH_DLC_DEFAULTS, **geometry}
    if x_end_m is None:
        x_end_m = tanh_dlc_settled_x(stretch, **g) + LEAD_OUT_M
    x = _x_grid(x_start_m, x_end_m, spacing_m)
    y, yp, ypp = tanh_dlc_geometry(x, stretch, **g)
    return _graph_path("tanh_dlc", x, y, yp, ypp, _speed_array(x, speed_mps, speed_profile_kmh))


def iso3888(
    speed_mps: float,
    vehicle_width_m: float = VEHICLE_WIDTH_M,
    lane_offset_m: float = 3.5,
    cone_margin_m: float = 0.0,
    x_start_m: float = DEFAULT_X_START_M,
    x_end_m: float | None = None,
    spacing_m: float = DEFAULT_SPACING_M,
    speed_profile_kmh: Sequence | None = None,
) -> ReferencePath:
    """Smooth centre line of the ISO 3888-1 double lane change (section 1 starts at X = 0)."""
    xc1, k1, xc2, k2 = iso3888_steepness(vehicle_width_m, lane_offset_m, cone_margin_m)
    if x_end_m is None:
        x_end_m = sum(ISO3888_SECTIONS_M) + LEAD_OUT_M
    x = _x_grid(x_start_m, x_end_m, spacing_m)
    h2 = lane_offset_m / 2.0
    t1, t2 = np.tanh(k1 * (x - xc1)), np.tanh(k2 * (x - xc2))
    s1, s2 = 1.0 - t1 * t1, 1.0 - t2 * t2
    y = h2 * (t1 - t2)
    yp = h2 * (k1 * s1 - k2 * s2)
    ypp = h2 * (-2.0 * k1 * k1 * t1 * s1 + 2.0 * k2 * k2 * t2 * s2)
    path = _graph_path("iso3888", x, y, yp, ypp, _speed_array(x, speed_mps, speed_profile_kmh))
    return dataclasses.replace(path, lanes=tuple(iso3888_lanes(vehicle_width_m, lane_offset_m)),
                               vehicle_width_m=vehicle_width_m)


def sine(
    speed_mps: float,
    amplitude_m: float = 1.0,
    wavelength_m: float = 60.0,
    periods: float = 2.0,
    x0_m: float = 0.0,
    ramp_m: float | None = None,
    x_start_m: float = DEFAULT_X_START_M,
    x_end_m: float | None = None,
    spacing_m: float = DEFAULT_SPACING_M,
    speed_profile_kmh: Sequence | None = None,
) -> ReferencePath:
    """Enveloped sine weave starting at ``x0_m``."""
    ramp = wavelength_m / 2.0 if ramp_m is None else ramp_m
    if not (wavelength_m > 0 and periods > 0 and 0 < ramp <= periods * wavelength_m / 2.0):
        raise ValueError("path: sine needs wavelength_m > 0, periods > 0, "
                         "0 < ramp_m <= periods*wavelength_m/2")
    if x_end_m is None:
        x_end_m = x0_m + periods * wavelength_m + LEAD_OUT_M
    x = _x_grid(x_start_m, x_end_m, spacing_m)
    y, yp, ypp = sine_geometry(x, amplitude_m, wavelength_m, periods, x0_m, ramp)
    return _graph_path("sine", x, y, yp, ypp, _speed_array(x, speed_mps, speed_profile_kmh))


def straight(
    speed_mps: float,
    x_start_m: float = DEFAULT_X_START_M,
    x_end_m: float = 200.0,
    spacing_m: float = DEFAULT_SPACING_M,
    speed_profile_kmh: Sequence | None = None,
) -> ReferencePath:
    """Straight line along X at Y = 0."""
    x = _x_grid(x_start_m, x_end_m, spacing_m)
    z = np.zeros_like(x)
    return _graph_path("straight", x, z, z, z, _speed_array(x, speed_mps, speed_profile_kmh))


def circle(
    speed_mps: float,
    radius_m: float = 40.0,
    lead_in_m: float = 20.0,
    transition_m: float = 20.0,
    arc_deg: float = 360.0,
    direction: str = "left",
    x_start_m: float = DEFAULT_X_START_M,
    spacing_m: float = DEFAULT_SPACING_M,
) -> ReferencePath:
    """Straight lead-in, clothoid, then a constant-radius arc."""
    if radius_m <= 0 or lead_in_m < 0 or transition_m < 0 or arc_deg <= 0:
        raise ValueError("path: circle needs radius_m > 0, lead_in_m >= 0, transition_m >= 0, "
                         "arc_deg > 0")
    if direction not in ("left", "right"):
        raise ValueError(f"path.direction: '{direction}' is not one of ['left', 'right']")
    sign = 1.0 if direction == "left" else -1.0
    arc_len = math.radians(arc_deg) * radius_m
    total = lead_in_m + transition_m + arc_len
    n = int(math.ceil(total / spacing_m)) + 1
    s = np.linspace(0.0, total, n)
    kappa_end = sign / radius_m
    ramp = np.clip((s - lead_in_m) / transition_m, 0.0, 1.0) if transition_m > 0 else (
        (s >= lead_in_m).astype(float))
    kappa = kappa_end * ramp
    # heading: exact integral of the piecewise-linear curvature
    s1, s2 = lead_in_m, lead_in_m + transition_m
    yaw = np.where(
        s <= s1, 0.0,
        np.where(s <= s2, kappa_end * (s - s1) ** 2 / (2.0 * max(transition_m, 1e-12)),
                 kappa_end * (transition_m / 2.0 + (s - s2))),
    )
    ds = np.diff(s)
    mid = 0.5 * (yaw[1:] + yaw[:-1])
    x = x_start_m + np.concatenate(([0.0], np.cumsum(ds * np.cos(mid))))
    y = np.concatenate(([0.0], np.cumsum(ds * np.sin(mid))))
    return ReferencePath(name="circle", x=x, y=y, yaw=yaw, curvature=kappa, s=s,
                         speed=np.full(s.shape, float(speed_mps)))


# --- scenario glue ----------------------------------------------------------------------

_BUILDERS = {"tanh_dlc": tanh_dlc, "iso3888": iso3888, "iso3888_2": iso3888_2,
             "circle": circle, "sine": sine, "straight": straight}


def path_from_mapping(
    d: Mapping[str, Any], speed_mps: float, x_end_m: float | None = None
) -> ReferencePath:
    """Build a path from a scenario's ``path:`` mapping. ``stretch: auto`` (tanh_dlc) means
    v/(10 m/s). ``x_end_m`` is the default end of the path when the mapping has none."""
    if not isinstance(d, Mapping):
        raise ValueError(f"path: expected a mapping, got {d!r}")
    params = dict(d)
    kind = params.pop("type", None)
    if kind not in _BUILDERS:
        raise ValueError(f"path.type: '{kind}' is not one of {sorted(_BUILDERS)}")
    if kind == "tanh_dlc" and params.get("stretch") == "auto":
        params["stretch"] = speed_mps / 10.0
    builder = _BUILDERS[kind]
    accepted = set(inspect.signature(builder).parameters) - {"speed_mps", "geometry"}
    if kind == "tanh_dlc":
        accepted |= set(TANH_DLC_DEFAULTS)
    unknown = set(params) - accepted
    if unknown:
        raise ValueError(f"path: unknown key(s) {sorted(unknown)} for type '{kind}'")
    for key, value in params.items():
        if key not in ("direction", "speed_profile_kmh") and (
            isinstance(value, bool) or not isinstance(value, int | float)
            or not math.isfinite(value)
        ):
            raise ValueError(f"path.{key}: expected a finite number, got {value!r}")
    if x_end_m is not None and "x_end_m" in accepted and "x_end_m" not in params:
        params["x_end_m"] = x_end_m
    return builder(speed_mps, **params)


def peak_lateral_accel_demand(path: ReferencePath, speed_mps: float | None = None) -> float:
    """max |κ| v² (m/s²) at ``speed_mps``, or along the path's own speed profile."""
    if speed_mps is None:
        return float(np.max(np.abs(path.curvature) * path.speed**2))
    return float(np.max(np.abs(path.curvature)) * speed_mps**2)


def lateral_error(path: ReferencePath, x: float, y: float, index: int | None = None) -> float:
    """Signed lateral offset of (x, y) from the path at its nearest point, m, left positive
    (projection on the nearest sample's normal); ``index``: that point's index if known
    (else a full search, :func:`fourws_common.path_lookup.nearest_sample`)."""
    i = nearest_sample(path.x, path.y, x, y) if index is None else index
    yaw = path.yaw[i]
    return float(-(x - path.x[i]) * math.sin(yaw) + (y - path.y[i]) * math.cos(yaw))
