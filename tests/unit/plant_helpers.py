"""A plant output for tests that need a state to measure, without a simulator."""

from __future__ import annotations

import numpy as np

from fourws_sim.core.plant_io import PlantOutputs


def plant_output(**fields) -> PlantOutputs:
    """A :class:`PlantOutputs` at rest on the x axis moving at 1 m/s (every other field zero,
    the wheel arrays ones), ``fields`` replacing any of them."""
    scalars = dict(t_s=0.0, x=0.0, y=0.0, yaw=0.0, vx=1.0, vy=0.0, yaw_rate=0.0, ax=0.0,
                   ay=0.0, sideslip=0.0, steer_front=0.0, steer_rear=0.0)
    arrays = {name: np.ones(4) for name in ("wheel_speed", "wheel_torque", "fx", "fy", "fz",
                                            "mu")}
    return PlantOutputs(**(scalars | arrays | fields))
