"""Conditions of a run: what the controllers see and how late their commands act.

A condition is the bench around the controllers, separate from the scenario (road, path,
speed): measurement noise per channel (``fourws_sim.core.sensing``), a computation delay of
N control periods, a steering dead time, where the allocator's and the MPC's tyre data come
from (``oracle``: the plant's true per-wheel F_z, F_y and μ, the paper's idealised setting;
``estimated``: ``fourws_torque_alloc.core.tyre_estimate`` from the measured a_x, a_y and a
configured nominal μ), MPC parameter overrides (model mismatch: the controller's mass,
inertia or cornering stiffness against the plant's), plant overrides over the scenario's
vehicle (``vehicle_overrides``, e.g. a slower steering actuator), and a seed. ``IDEAL`` is
the paper's setting. In a realistic condition the controllers receive a
:class:`MeasuredState`, which carries no tyre force and no road adhesion at all, so no plant
truth can leak into them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fourws_sim.core.sensing import CHANNELS, NoiseSpec, noise_specs

TYRE_SOURCES = ("oracle", "estimated")


@dataclass(frozen=True)
class Condition:
    """One condition (module docstring); SI units."""

    name: str = "ideal"
    noise: Mapping[str, NoiseSpec] = field(default_factory=dict)
    delay_periods: int = 0
    steer_dead_time_s: float = 0.0
    tyre_forces: str = "oracle"
    mu_nominal: float = 0.8
    mpc_overrides: Mapping[str, Any] = field(default_factory=dict)
    vehicle_overrides: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0

    def __post_init__(self) -> None:
        if self.tyre_forces not in TYRE_SOURCES:
            raise ValueError(f"tyre_forces: '{self.tyre_forces}' is not one of {TYRE_SOURCES}")
        if not (isinstance(self.delay_periods, int) and 0 <= self.delay_periods <= 100):
            raise ValueError(f"delay_periods: expected an integer 0..100, got "
                             f"{self.delay_periods!r}")
        if not 0.01 <= self.mu_nominal <= 3.0:
            raise ValueError(f"mu_nominal: {self.mu_nominal} outside 0.01..3")
        unknown = sorted(set(self.noise) - set(CHANNELS))
        if unknown:
            raise ValueError(f"noise: unknown channel(s) {unknown}")

    @property
    def ideal(self) -> bool:
        """The paper's setting: truth in, no delay, oracle tyre data, no override."""
        return (not any(s.sigma > 0.0 for s in self.noise.values()) and not self.delay_periods
                and not self.steer_dead_time_s and self.tyre_forces == "oracle"
                and not self.mpc_overrides and not self.vehicle_overrides)


IDEAL = Condition()

_KEYS = {"name", "noise", "delay_periods", "steer_dead_time_ms", "tyre_forces", "mu_nominal",
         "mpc_overrides", "vehicle_overrides", "seed"}


def condition_from_mapping(d: Mapping[str, Any], seed: int | None = None) -> Condition:
    """From YAML: ``noise: {y: {sigma: 0.02, tau_s: 1.0}, ...}``, ``delay_periods``,
    ``steer_dead_time_ms``, ``tyre_forces``, ``mu_nominal``, ``mpc_overrides``, ``seed``."""
    unknown = sorted(set(d) - _KEYS)
    if unknown:
        raise ValueError(f"condition: unknown key(s) {unknown} (known: {sorted(_KEYS)})")
    return Condition(
        name=str(d.get("name", "condition")), noise=noise_specs(d.get("noise")),
        delay_periods=int(d.get("delay_periods", 0)),
        steer_dead_time_s=float(d.get("steer_dead_time_ms", 0.0)) * 1e-3,
        tyre_forces=str(d.get("tyre_forces", "oracle")),
        mu_nominal=float(d.get("mu_nominal", 0.8)),
        mpc_overrides=dict(d.get("mpc_overrides") or {}),
        vehicle_overrides=dict(d.get("vehicle_overrides") or {}),
        seed=int(d["seed"]) if seed is None and "seed" in d else int(seed or 0))


@dataclass
class MeasuredState:
    """What a car's sensors give the controllers (no tyre forces, no road adhesion)."""

    t_s: float
    x: float
    y: float
    yaw: float
    vx: float
    vy: float
    yaw_rate: float
    ax: float
    ay: float
    steer_front: float
    steer_rear: float
    wheel_speed: np.ndarray

    @classmethod
    def of(cls, out: Any) -> MeasuredState:
        """The measurable fields of the plant's outputs (copied)."""
        return cls(out.t_s, out.x, out.y, out.yaw, out.vx, out.vy, out.yaw_rate, out.ax,
                   out.ay, out.steer_front, out.steer_rear, np.array(out.wheel_speed))
