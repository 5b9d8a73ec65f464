"""Estimates per-wheel F_z, F_y and μ without plant truth: what a car's controller can know.

The allocator's ``tyre_forces: estimated`` (docs/lower-layer.md, "Tyre data"). From the
measured accelerations a_x, a_y (IMU, m/s², ISO body frame) and the controller's own nominal
vehicle constants (the plant's names, the car file):

* **F_z**, static load plus quasi-static load transfer
  (:func:`fourws_common.load_transfer.wheel_loads`, shared with the MPC).
* **F_y**, the single-track model in quasi-steady cornering (yaw moment balance, ṙ ≈ 0):
  F_y,front axle = m a_y b/L, F_y,rear axle = m a_y a/L, each axle's force shared by its two
  wheels in proportion to their estimated loads.
* **μ**, a configured nominal for every wheel: the controller does not know the road.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from fourws_common.load_transfer import LoadGeometry, wheel_loads


@dataclass(frozen=True)
class EstimatorParams(LoadGeometry):
    """Nominal constants of the estimate (SI; names as in the car file): the loads' geometry
    and the nominal μ."""

    mu_nominal: float

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> EstimatorParams:
        """The fields from ``values`` (a car file's mapping and ``mu_nominal``); the car file
        is their one owner, so a missing one is a ``ValueError`` naming it."""
        names = [f.name for f in fields(cls)]
        missing = [k for k in names if k not in values]
        if missing:
            raise ValueError(f"tyre estimate: missing {missing}")
        return cls(**{k: float(values[k]) for k in names})


class TyreEstimator:
    """F_z, F_y (N, FL FR RL RR) and μ from a_x, a_y (module docstring)."""

    def __init__(self, p: EstimatorParams) -> None:
        self.p = p
        length = p.cg_to_front_axle_m + p.cg_to_rear_axle_m
        self._fy_share = (p.cg_to_rear_axle_m / length, p.cg_to_front_axle_m / length)

    def fz(self, ax: float, ay: float) -> np.ndarray:
        """Wheel loads (4,), N."""
        return np.array(wheel_loads(ax, ay, self.p))

    def estimate(self, ax: float, ay: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(F_z (4,), F_y (4,), μ (4,))."""
        fz = self.fz(ax, ay)
        m_ay = self.p.mass_kg * ay
        fy = np.empty(4)
        for axle, (i, j) in enumerate(((0, 1), (2, 3))):
            total = m_ay * self._fy_share[axle]
            load = fz[i] + fz[j]
            share_i = 0.5 if load <= 0.0 else fz[i] / load
            fy[i], fy[j] = total * share_i, total * (1.0 - share_i)
        return fz, fy, np.full(4, self.p.mu_nominal)


class TyreData:
    """The allocator's per-wheel (F_z, F_y, μ) of a state, from its config's ``tyre_forces``:
    ``oracle`` reads the state's own fz, fy, mu fields (the plant's truth, the paper's
    idealised setting); ``estimated`` computes them from the state's measured a_x, a_y with
    :class:`TyreEstimator` on the config's vehicle constants (front and rear track B)."""

    def __init__(self, cfg: Any) -> None:
        self.source = cfg.tyre_forces
        self.estimator: TyreEstimator | None = None
        if self.source == "estimated":
            self.estimator = TyreEstimator(EstimatorParams(
                mass_kg=cfg.mass_kg, cg_to_front_axle_m=cfg.cg_to_front_axle_m,
                cg_to_rear_axle_m=cfg.cg_to_rear_axle_m, cg_height_m=cfg.cg_height_m,
                track_width_front_m=cfg.track_width_m, track_width_rear_m=cfg.track_width_m,
                roll_stiffness_front_share=cfg.roll_stiffness_front_share,
                gravity_mps2=cfg.gravity_mps2, mu_nominal=cfg.mu_nominal))

    def of(self, state: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(F_z (4,), F_y (4,), μ (4,)) for ``state`` (attributes fz, fy, mu or ax, ay)."""
        if self.estimator is None:
            return (np.asarray(state.fz, dtype=float), np.asarray(state.fy, dtype=float),
                    np.asarray(state.mu, dtype=float))
        return self.estimator.estimate(float(state.ax), float(state.ay))
