"""Gives the road adhesion μ under each wheel's contact point.

Three kinds, built from a scenario's ``road:`` mapping by :func:`road_from_mapping`
(docs/plant.md, "Scenarios"):

* ``constant``     {type: constant, mu: 0.5}
* ``piecewise_x``  {type: piecewise_x, x_m: [x1, x2, ...], mu: [μ0, μ1, μ2, ...]}:
  μ0 for X < x1, μ1 for x1 ≤ X < x2, ... (μ steps along the inertial X axis; len(mu) =
  len(x_m) + 1, x_m strictly increasing)
* ``split``        {type: split, mu_left: 0.8, mu_right: 0.3}: μ by the side of the vehicle
  the wheel is on (FL, RL left; FR, RR right), as in a split-μ straight-line test where the
  car straddles the boundary.

``mu_at(x, y, side)`` is vectorised over the four contact points (side +1 left, −1 right).
The simulator samples μ at the start of every integration substep (a step in μ is resolved
to one substep, 1 ms, i.e. 2.5 cm at 90 km/h) through the plain-float :meth:`Road.mu4`.
"""

from __future__ import annotations

import bisect
import math
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

MU_MIN, MU_MAX = 0.05, 1.5


def _check_mu(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"road.{name}: expected a number, got {value!r}")
    v = float(value)
    if not (math.isfinite(v) and MU_MIN <= v <= MU_MAX):
        raise ValueError(f"road.{name}: {v} is outside [{MU_MIN}, {MU_MAX}]")
    return v


class Road(ABC):
    """Adhesion coefficient of the road surface."""

    uniform: bool = False
    """True when μ does not depend on the position (the simulator then skips the lookup)."""

    @abstractmethod
    def mu_at(self, x: np.ndarray, y: np.ndarray, side: np.ndarray) -> np.ndarray:
        """μ (4,) at contact points X, Y (m, inertial) on wheel sides ``side`` (+1 / −1)."""

    @abstractmethod
    def mu4(self, xs: Sequence[float], ys: Sequence[float]) -> tuple[float, float, float, float]:
        """Plain-float μ of the four wheels FL FR RL RR at contact points (xs, ys)."""

    @abstractmethod
    def mu_min(self) -> float:
        """The lowest μ anywhere on this road."""

    @abstractmethod
    def describe(self) -> str:
        """Short human description."""


class ConstantRoad(Road):
    uniform = True

    def __init__(self, mu: float) -> None:
        self.mu = _check_mu("mu", mu)
        self._mu4 = (self.mu,) * 4

    def mu_at(self, x, y, side):
        return np.full(np.shape(x), self.mu)

    def mu4(self, xs, ys):
        return self._mu4

    def mu_min(self) -> float:
        return self.mu

    def describe(self) -> str:
        return f"μ = {self.mu:g}"


class PiecewiseXRoad(Road):
    def __init__(self, x_m: Sequence[float], mu: Sequence[float]) -> None:
        self.x_m = [float(v) for v in x_m]
        self.mu = [_check_mu(f"mu[{i}]", v) for i, v in enumerate(mu)]
        if len(self.mu) != len(self.x_m) + 1:
            raise ValueError(
                f"road.mu: piecewise_x needs len(mu) = len(x_m) + 1, got {len(self.mu)} and "
                f"{len(self.x_m)}"
            )
        if not all(math.isfinite(v) for v in self.x_m) or any(
            b <= a for a, b in zip(self.x_m, self.x_m[1:], strict=False)
        ):
            raise ValueError(f"road.x_m: must be finite and strictly increasing, got {self.x_m}")

    def mu_at(self, x, y, side):
        idx = np.searchsorted(np.asarray(self.x_m), np.asarray(x, dtype=float), side="right")
        return np.asarray(self.mu)[idx]

    def mu4(self, xs, ys):
        xm, mu = self.x_m, self.mu
        r = bisect.bisect_right
        return (mu[r(xm, xs[0])], mu[r(xm, xs[1])], mu[r(xm, xs[2])], mu[r(xm, xs[3])])

    def mu_min(self) -> float:
        return min(self.mu)

    def describe(self) -> str:
        parts = [f"{self.mu[0]:g}"]
        for x, m in zip(self.x_m, self.mu[1:], strict=True):
            parts.append(f"{m:g} from X = {x:g} m")
        return "μ = " + ", ".join(parts)


class SplitRoad(Road):
    uniform = True

    def __init__(self, mu_left: float, mu_right: float) -> None:
        self.mu_left = _check_mu("mu_left", mu_left)
        self.mu_right = _check_mu("mu_right", mu_right)
        self._mu4 = (self.mu_left, self.mu_right, self.mu_left, self.mu_right)

    def mu_at(self, x, y, side):
        return np.where(np.asarray(side) > 0, self.mu_left, self.mu_right).astype(float)

    def mu4(self, xs, ys):
        return self._mu4

    def mu_min(self) -> float:
        return min(self.mu_left, self.mu_right)

    def describe(self) -> str:
        return f"split μ: left {self.mu_left:g}, right {self.mu_right:g}"


def road_from_mapping(d: Mapping[str, Any]) -> Road:
    """Build a road from a scenario's ``road:`` mapping; ``ValueError`` names a bad key."""
    if not isinstance(d, Mapping):
        raise ValueError(f"road: expected a mapping, got {d!r}")
    kind = d.get("type", "constant")
    allowed = {
        "constant": {"type", "mu"},
        "piecewise_x": {"type", "x_m", "mu"},
        "split": {"type", "mu_left", "mu_right"},
    }
    if kind not in allowed:
        raise ValueError(f"road.type: '{kind}' is not one of {sorted(allowed)}")
    unknown = set(d) - allowed[kind]
    if unknown:
        raise ValueError(f"road: unknown key(s) {sorted(unknown)} for type '{kind}'")
    try:
        if kind == "constant":
            return ConstantRoad(d["mu"])
        if kind == "piecewise_x":
            return PiecewiseXRoad(list(d["x_m"]), list(d["mu"]))
        return SplitRoad(d["mu_left"], d["mu_right"])
    except KeyError as exc:
        raise ValueError(f"road: missing key {exc.args[0]!r} for type '{kind}'") from None
