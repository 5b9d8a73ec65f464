"""Computes the reference: nearest point, path-frame errors and the horizon's reference outputs.

The reference comes as arrays x, y, yaw, curvature, speed at fine spacing (as in the
ReferenceTrajectory message); the arc length s is their cumulative chord length
(docs/mpc.md, "Reference and frames").

Nearest point: every segment p_i → p_{i+1} in a window around the previous index (or all
segments on the first call, or when the best lies on the window's edge: the project's one
windowed search, ``fourws_common.path_lookup.windowed_search``) is projected on,
t = clip((p − p_i)·d / |d|², 0, 1); the closest projection wins. Beyond the first/last
sample the projection continues along the end segments (t unclipped there), so s may leave
[0, s_end]. Errors in the path frame at the projection::

    e_Y = d̂ × (p − p_i)        (signed lateral offset, left of the path positive)
    e_φ = wrap(ψ − ψ_ref(s))    wrapped to (−π, π]

Reference outputs over the horizon at the preview arc lengths s + vx T i, i = 1..Np
(linear interpolation of x, y and the unwrapped yaw; straight extrapolation beyond the ends):

* ``frame="path"`` (what the controller uses): coordinates in the frame whose origin is the
  projection point and whose X axis is the path tangent ψ0 there; Y_ref,i is the rotated
  offset, φ_ref,i = ψ_ref,i − ψ0. The vehicle is then at X = 0 (to first order), Y = e_Y,
  φ = e_φ.
* ``frame="global"``: the paper's Y and φ in the map frame, with φ_ref shifted by a multiple
  of 2π so that it is within π of the vehicle's yaw.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from fourws_common.input_guard import check_reference
from fourws_common.path_lookup import windowed_search

TWO_PI = 2.0 * math.pi
#: default nearest-point window (samples behind / ahead of the last index; MpcConfig's
#: ref_search_back / ref_search_ahead)
SEARCH_BACK = 50
SEARCH_AHEAD = 400


def wrap_angle(a: float | np.ndarray) -> float | np.ndarray:
    """Wrap to (−π, π]."""
    if isinstance(a, float | int):
        w = math.fmod(a + math.pi, TWO_PI)
        w = w + TWO_PI if w < 0.0 else w
        w -= math.pi
        return math.pi if w == -math.pi else w
    w = np.mod(np.asarray(a, float) + math.pi, TWO_PI) - math.pi
    w = np.where(w == -math.pi, math.pi, w)
    return float(w) if np.ndim(w) == 0 else w


class NearestPoint(NamedTuple):
    """Projection of a position on the reference path (a named tuple: built every step)."""

    index: int            # start sample of the segment
    s: float              # m, arc length of the projection
    x: float
    y: float
    yaw: float            # rad, path heading at s (unwrapped as in the arrays)
    curvature: float      # 1/m
    speed: float          # m/s
    lateral_error: float  # m, left positive


class PathErrors(NamedTuple):
    """Lateral and heading error of a pose to the path, with the projection point."""

    lateral_error: float   # m
    heading_error: float   # rad, (−π, π]
    near: NearestPoint


@dataclass(frozen=True, eq=False)
class Reference:
    """Immutable reference path with arc length; build with :meth:`from_arrays`."""

    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    curvature: np.ndarray
    speed: np.ndarray
    s: np.ndarray
    search_back: int = SEARCH_BACK
    search_ahead: int = SEARCH_AHEAD

    @classmethod
    def from_arrays(cls, x, y, yaw, curvature, speed, *, search_back: int = SEARCH_BACK,
                    search_ahead: int = SEARCH_AHEAD) -> Reference:
        """Validate and build. Arrays of one length N ≥ 2, finite, distinct consecutive points.

        Raises ``ValueError`` naming the bad array (also for absurd magnitudes,
        :func:`fourws_common.input_guard.check_reference`).
        """
        check_reference(x, y, yaw, curvature, speed)
        arrs = {name: np.array(a, dtype=float)
                for name, a in (("x", x), ("y", y), ("yaw", yaw), ("curvature", curvature),
                                ("speed", speed))}
        arrs["yaw"] = np.unwrap(arrs["yaw"])
        seg = np.hypot(np.diff(arrs["x"]), np.diff(arrs["y"]))
        s = np.concatenate([[0.0], np.cumsum(seg)])
        for v in (*arrs.values(), s):
            v.setflags(write=False)
        return cls(arrs["x"], arrs["y"], arrs["yaw"], arrs["curvature"], arrs["speed"], s,
                   int(search_back), int(search_ahead))

    @property
    def length(self) -> float:
        """Total arc length (m)."""
        return float(self.s[-1])

    def _project(self, px: float, py: float, lo: int, hi: int
                 ) -> tuple[int, float, float]:
        """Best segment in [lo, hi) → (index, t (unclipped at the path ends), signed offset)."""
        return _project(self.x, self.y, float(px), float(py), int(lo), int(hi))

    def nearest(self, px: float, py: float, hint: int | None = None) -> NearestPoint:
        """Projection of (px, py) on the path; ``hint`` is the previous index (the window
        search of :func:`fourws_common.path_lookup.windowed_search`, ``search_back``
        segments behind it and ``search_ahead`` ahead)."""
        i, t, off = windowed_search(lambda lo, hi: self._project(px, py, lo, hi),
                                    len(self.x) - 1, None if hint is None else int(hint),
                                    self.search_back, self.search_ahead)
        seg_len = self.s[i + 1] - self.s[i]
        s = float(self.s[i] + t * seg_len)
        if 0.0 <= t <= 1.0:
            j = i + 1

            def lerp(a: np.ndarray) -> float:
                return float(a[i] + t * (a[j] - a[i]))

            return NearestPoint(i, s, lerp(self.x), lerp(self.y), lerp(self.yaw),
                                lerp(self.curvature), lerp(self.speed), off)
        x, y, yaw, kappa, v = self.sample(np.array([s]))
        return NearestPoint(i, s, float(x[0]), float(y[0]), float(yaw[0]), float(kappa[0]),
                            float(v[0]), off)

    def errors(self, px: float, py: float, yaw: float, hint: int | None = None) -> PathErrors:
        """Signed lateral error (m, left +) and heading error (rad, (−π, π]) of a pose."""
        near = self.nearest(px, py, hint)
        return PathErrors(near.lateral_error, wrap_angle(yaw - near.yaw), near)

    def sample(self, s_query: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """x, y, yaw, curvature, speed at arc lengths ``s_query`` (any shape).

        Linear interpolation inside; beyond the ends the path continues straight along the end
        heading with the end curvature set to zero and the end speed held.
        """
        sq = np.asarray(s_query, float)
        s = self.s
        x, y, yaw = (a.reshape(sq.shape) for a in _pose_at(s, self.x, self.y, self.yaw,
                                                             np.ascontiguousarray(sq.ravel())))
        kappa = np.where((sq > s[-1]) | (sq < s[0]), 0.0, np.interp(sq, s, self.curvature))
        return x, y, yaw, kappa, np.interp(sq, s, self.speed)

    def horizon(self, near: NearestPoint, vx: float, dt_s: float, n_p: int,
                vehicle_yaw: float, frame: str = "path") -> tuple[np.ndarray, np.ndarray]:
        """Reference outputs (φ_ref, Y_ref), each (Np,), at s + vx T i, i = 1..Np.

        ``frame`` "path" (origin at ``near``, X along its tangent) or "global" (map frame, φ_ref
        within π of ``vehicle_yaw``). See the module docstring.
        """
        if frame not in ("path", "global"):
            raise ValueError(f"frame: '{frame}' is not one of ['path', 'global']")
        # global: φ_ref within π of the vehicle's yaw (a NaN yaw raises here)
        shift = (0.0 if frame == "path"
                 else TWO_PI * round((vehicle_yaw - near.yaw) / TWO_PI))
        return _horizon(self.s, self.x, self.y, self.yaw, float(near.s), float(near.x),
                        float(near.y), float(near.yaw), max(float(vx), 0.0) * float(dt_s),
                        int(n_p), frame == "path", shift)

    def to_path_frame(self, near: NearestPoint, px: float, py: float, yaw: float
                      ) -> tuple[float, float, float]:
        """Pose (X, Y, φ) in the path frame at ``near`` (φ wrapped to (−π, π])."""
        c, s = math.cos(near.yaw), math.sin(near.yaw)
        dx, dy = px - near.x, py - near.y
        return c * dx + s * dy, -s * dx + c * dy, wrap_angle(yaw - near.yaw)


@njit(cache=True)
def _project(xs: np.ndarray, ys: np.ndarray, px: float, py: float, lo: int, hi: int
             ) -> tuple[int, float, float]:
    """:meth:`Reference._project`, compiled: the first segment of least distance wins."""
    best, k = np.inf, lo
    for i in range(lo, hi):
        dx, dy = xs[i + 1] - xs[i], ys[i + 1] - ys[i]
        rx, ry = px - xs[i], py - ys[i]
        t = min(max((rx * dx + ry * dy) / (dx * dx + dy * dy), 0.0), 1.0)
        ex, ey = rx - t * dx, ry - t * dy
        d2 = ex * ex + ey * ey
        if d2 < best:
            best, k = d2, i
    dx, dy = xs[k + 1] - xs[k], ys[k + 1] - ys[k]
    rx, ry = px - xs[k], py - ys[k]
    L2 = dx * dx + dy * dy
    t_raw = (rx * dx + ry * dy) / L2
    t = min(max(t_raw, 0.0), 1.0)
    nseg = xs.shape[0] - 1
    if (k == 0 and t_raw < 0.0) or (k == nseg - 1 and t_raw > 1.0):
        t = t_raw
    return k, t, (dx * ry - dy * rx) / math.sqrt(L2)


@njit(cache=True)
def _pose_at(s: np.ndarray, xs: np.ndarray, ys: np.ndarray, yaws: np.ndarray,
             sq: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """x, y, yaw at the arc lengths ``sq`` (:meth:`Reference.sample`'s pose): linear
    interpolation inside, the end headings continued straight beyond the ends."""
    x = np.interp(sq, s, xs)
    y = np.interp(sq, s, ys)
    yaw = np.interp(sq, s, yaws)
    last = s.shape[0] - 1
    for i in range(sq.shape[0]):
        if sq[i] > s[last]:
            d = sq[i] - s[last]
            x[i] = xs[last] + d * math.cos(yaws[last])
            y[i] = ys[last] + d * math.sin(yaws[last])
        elif sq[i] < s[0]:
            d = sq[i] - s[0]
            x[i] = xs[0] + d * math.cos(yaws[0])
            y[i] = ys[0] + d * math.sin(yaws[0])
    return x, y, yaw


@njit(cache=True)
def _horizon(s: np.ndarray, xs: np.ndarray, ys: np.ndarray, yaws: np.ndarray, s0: float,
             x0: float, y0: float, yaw0: float, ds: float, n_p: int, path_frame: bool,
             shift: float) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`Reference.horizon`, compiled: the poses at s0 + ds i, i = 1..N_p, as (φ_ref,
    Y_ref) in the path frame at (x0, y0, yaw0), or in the map frame with φ_ref shifted by
    ``shift`` (a whole number of turns)."""
    sq = np.empty(n_p)
    for i in range(n_p):
        sq[i] = s0 + ds * (i + 1)
    x, y, yaw = _pose_at(s, xs, ys, yaws, sq)
    if path_frame:
        c, sn = math.cos(yaw0), math.sin(yaw0)
        return yaw - yaw0, -sn * (x - x0) + c * (y - y0)
    return yaw + shift, y
