"""Nearest point on a sampled path, with a moving search window (pure numpy).

Given path samples (x_i, y_i) in increasing arc length, :class:`PathIndex` returns the index
of the sample nearest to a position, searching a window around the previous answer so the
cost per call is constant; a full search is done on the first call and whenever the window
answer lies on its edge. Used by the speed controller for the reference speed; the MPC has its
own projection in ``fourws_mpc.core.reference``.
"""

from __future__ import annotations

import numpy as np

from fourws_common.input_guard import REF_POSITION_MAX_M, REF_SPEED_MAX_MPS


class PathIndex:
    """Nearest-sample lookup on a path; ``x``, ``y`` shape (N,), m."""

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
        """Index of the sample nearest to (px, py)."""
        n = self.x.size
        if self._last is not None:
            lo = max(0, self._last - self.window)
            hi = min(n, self._last + self.window + 1)
            d2 = (self.x[lo:hi] - px) ** 2 + (self.y[lo:hi] - py) ** 2
            i = lo + int(np.argmin(d2))
            if (i > lo or lo == 0) and (i < hi - 1 or hi == n):
                self._last = i
                return i
        d2 = (self.x - px) ** 2 + (self.y - py) ** 2
        self._last = int(np.argmin(d2))
        return self._last


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
