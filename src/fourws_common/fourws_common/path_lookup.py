"""Nearest point on a sampled path, with a moving search window (pure numpy).

:func:`windowed_search` is the one search of the project for the point of a path nearest to
a position (docs/architecture.md, "One owner per fact"); what is measured is its caller's
(``best``). With the previous answer ``hint`` it searches the window [hint − back, hint + ahead)
of the n candidates (clipped to [0, n)); with no hint (the first call), or when the window's
best lies on an edge of the window that is not an end of the path, it searches all n. Its
answer is therefore the full search's whenever the nearest candidate moves by less than the
window between calls, which holds unless the path comes back near itself.

Its users, each with its own measure and window:

* :class:`PathIndex`: the nearest *sample* (squared distance, :func:`nearest_sample`; the
  first of equal distances, as ``np.argmin``), ``window`` samples either side (200): the
  speed controller's reference speed (:class:`SpeedProfile`) and the plant's abort check
  (``fourws_sim.core.scenario.Scenario.check_end``);
* ``fourws_mpc.core.reference.Reference.nearest``: the nearest *segment* (projection on each
  segment), ``ref_search_back`` segments behind and ``ref_search_ahead`` ahead;
* :func:`nearest_sample` alone is the full search (the scenario's on-path start,
  ``fourws_sim.core.paths.lateral_error`` without an index).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import numpy as np

from fourws_common.input_guard import REF_POSITION_MAX_M, REF_SPEED_MAX_MPS

Found = TypeVar("Found", bound=tuple)


def windowed_search(best: Callable[[int, int], Found], n: int, hint: int | None, back: int,
                    ahead: int) -> Found:
    """The nearest of ``n`` candidates (samples or segments) by ``best``, searching around
    ``hint``; see the module docstring.

    ``best(lo, hi)`` measures the candidates lo..hi−1 and returns a tuple whose first item is
    the index (in 0..n−1) of the best of them; that tuple is returned.
    """
    if hint is not None:
        lo, hi = max(0, hint - back), min(n, hint + ahead)
        if lo < hi:                      # else a hint off the candidates: the whole search
            found = best(lo, hi)
            i = found[0]
            if not ((i == lo and lo > 0) or (i == hi - 1 and hi < n)):
                return found
    return best(0, n)


def nearest_sample(x: np.ndarray, y: np.ndarray, px: float, py: float, lo: int = 0,
                   hi: int | None = None) -> int:
    """Index of the sample of ``x[lo:hi]``, ``y[lo:hi]`` nearest to (px, py) (the first of
    equal distances); all samples by default."""
    d2 = x[lo:hi] - px                  # (x − px)² + (y − py)², in place
    d2 *= d2
    dy = y[lo:hi] - py
    dy *= dy
    d2 += dy
    return lo + int(d2.argmin())


class PathIndex:
    """Nearest-sample lookup on a path that remembers its last answer; ``x``, ``y`` shape
    (N,), m; :func:`windowed_search` with ``window`` samples either side."""

    def __init__(self, x: np.ndarray, y: np.ndarray, window: int = 200) -> None:
        self.x = np.asarray(x, dtype=float)
        self.y = np.asarray(y, dtype=float)
        if self.x.shape != self.y.shape or self.x.ndim != 1 or self.x.size < 2:
            raise ValueError("path needs x and y of equal length >= 2")
        if not (np.all(np.isfinite(self.x)) and np.all(np.isfinite(self.y))):
            raise ValueError("path holds non-finite coordinates")
        big = max(float(np.max(np.abs(self.x))), float(np.max(np.abs(self.y))))
        if big > REF_POSITION_MAX_M:
            raise ValueError(f"path coordinates up to {big:.3g} m, beyond {REF_POSITION_MAX_M:g}")
        self.window = window
        self._last: int | None = None

    def nearest(self, px: float, py: float) -> int:
        """Index of the sample nearest to (px, py) (a full search on the first call)."""
        x, y = self.x, self.y
        (i,) = windowed_search(lambda lo, hi: (nearest_sample(x, y, px, py, lo, hi),),
                               x.size, self._last, self.window, self.window + 1)
        self._last = i
        return i


class SpeedProfile:
    """Reference speed v (m/s) and its feed-forward acceleration a = v·dv/ds (m/s²) at the
    path sample nearest to the car. The one lookup both speed_pid_node and the in-process
    closed loop use, so the two give the same drive demand."""

    def __init__(self, x: np.ndarray, y: np.ndarray, speed: np.ndarray) -> None:
        self.index = PathIndex(x, y)
        self.speed = np.asarray(speed, dtype=float)
        if self.speed.shape != self.index.x.shape or not np.all(np.isfinite(self.speed)):
            raise ValueError("speed profile missing, of the wrong length or non-finite")
        if np.any(self.speed < 0.0) or np.any(self.speed > REF_SPEED_MAX_MPS):
            raise ValueError(f"speed profile outside 0..{REF_SPEED_MAX_MPS:g} m/s")
        ds = np.hypot(np.diff(self.index.x), np.diff(self.index.y))
        dv_ds = np.diff(self.speed) / np.maximum(ds, 1e-9)
        self.accel = self.speed * np.append(dv_ds, dv_ds[-1])

    def at(self, px: float, py: float) -> tuple[float, float]:
        """(v_ref m/s, a_ref m/s²) at the sample nearest to (px, py)."""
        i = self.index.nearest(px, py)
        return float(self.speed[i]), float(self.accel[i])
