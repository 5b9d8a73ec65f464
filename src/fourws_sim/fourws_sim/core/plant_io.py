"""Defines what the plant starts from and reports: :class:`InitialState`, :class:`PlantOutputs`.

The data the scenario (which builds the initial state and judges the outputs) and the
simulator (which starts from the one and produces the other) share; neither module imports
the other for them (docs/plant.md).

``PlantOutputs`` holds every field of the VehicleState message (SI units): accelerations are
accelerometer-style body-frame CG accelerations a_x = v̇x − v_y r, a_y = v̇y + v_x r; the
per-wheel ``fx``/``fy`` are tyre forces in each wheel's own frame; ``yaw`` is continuous
(not wrapped), like the paths' heading. Wheel arrays follow ``fourws_common.wheels.Wheel``.
The message's fields: docs/graph.md, "Interfaces".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class InitialState:
    """Initial pose and motion, SI: m, rad, m/s, rad/s."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0
    speed: float = 0.0
    vy: float = 0.0
    yaw_rate: float = 0.0

    def __post_init__(self) -> None:
        for name in ("x", "y", "yaw", "speed", "vy", "yaw_rate"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"initial.{name}: must be finite")


@dataclass
class PlantOutputs:
    """Every field of the VehicleState message, SI; wheel arrays (4,) FL FR RL RR."""

    t_s: float
    x: float
    y: float
    yaw: float
    vx: float
    vy: float
    yaw_rate: float
    ax: float
    ay: float
    sideslip: float
    steer_front: float
    steer_rear: float
    wheel_speed: np.ndarray
    wheel_torque: np.ndarray
    fx: np.ndarray
    fy: np.ndarray
    fz: np.ndarray
    mu: np.ndarray
