"""Metrics at the limit of grip (docs/limits.md, "Metrics and rules"), from a run's per-step arrays.

All on the plant's truth (the log's state), with μ the road's true mean adhesion under the
car at each step::

    demand_mug          = max κ v_ref² / (μ g) over the path ahead of the run (the rung)
    max_abs_sideslip_deg (metrics.py), yaw_rate_ratio = max |r| / (μ g / v_x)
    spin                = |β| ≥ SPIN_SIDESLIP_DEG at any step, or an abort on sideslip
    cone_excess_m       = on a cone course (``ReferencePath.lanes``), the largest distance
                          by which the body's width (the course's ``vehicle_width_m``, 1.5 m
                          on the shipped courses; centred on the CG)
                          reaches beyond a lane's edge while the CG is within the lane's X
                          range. The yawed footprint is not checked: the courses' centre
                          lines are built for the width alone (``paths.cone_steepness``)
    lane_violation      = cone_excess_m > 0 on a cone course; elsewhere max |e_Y| >
                          lane_free_m(w) (the free half-width of the ISO 3888-1 side lane
                          for a car of width w: (1.2 w + 0.25 − w)/2, 0.275 m at 1.5 m)
    speed_error_max_mps = max |v_x − v_ref|, v_ref the path speed at the nearest sample
    unmet_fx_max_n      = max |T_total − Σ T_i| / R          (drive force demanded − delivered)
    unmet_mz_max_nm     = max |M_z − (B/2R)(T_FR − T_FL + T_RR − T_RL)|   (yaw moment likewise)
    completed_clean     = completed and not spin and not lane_violation

The headline of a controller is the highest rung it completes clean.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from fourws_bringup.core.metrics import path_nearest
from fourws_common.wheels import Wheel
from fourws_sim.core.paths import VEHICLE_WIDTH_M

#: a run spins when |β| reaches this (deg): beyond the ~5-7° where a car's rear saturates,
#: where a driver has lost the car (stated criterion of the bench)
SPIN_SIDESLIP_DEG = 10.0
G = 9.81


def lane_free_m(vehicle_width_m: float = VEHICLE_WIDTH_M) -> float:
    """Free half-width (m) of the ISO 3888-1 side lane, 1.2 w + 0.25, for a car of width w:
    the lane rule where a course has no cones (0.275 m for the default 1.5 m)."""
    return (1.2 * vehicle_width_m + 0.25 - vehicle_width_m) / 2.0


#: the lane rule of the default car (m)
LANE_FREE_M = lane_free_m()


def delivered_yaw_moment(torque_nm: np.ndarray, track_m: float, radius_m: float
                         ) -> np.ndarray:
    """M_z (n,) of wheel torques (n, 4): (B/2R)(T_FR − T_FL + T_RR − T_RL)."""
    t = np.asarray(torque_nm, float).reshape(-1, 4)
    return track_m / (2.0 * radius_m) * (t[:, Wheel.FR] - t[:, Wheel.FL]
                                         + t[:, Wheel.RR] - t[:, Wheel.RL])


def cone_excess(lanes: tuple, x: np.ndarray, y: np.ndarray,
                vehicle_width_m: float = VEHICLE_WIDTH_M) -> float:
    """The largest distance (m, ≥ 0) the body's width reaches beyond a lane's cones
    (module docstring); 0 without lanes."""
    half = np.full(np.shape(x), 0.5 * vehicle_width_m)
    worst = 0.0
    for x0, x1, yc, width in lanes:
        inside = (x >= x0) & (x <= x1)
        if inside.any():
            worst = max(worst, float(np.max(np.abs(y[inside] - yc) + half[inside]
                                            - width / 2.0)))
    return max(worst, 0.0)


def braking_distance(x: np.ndarray, vx: np.ndarray, v_ref: np.ndarray) -> float:
    """X travelled (m) from where the reference speed starts to fall (0.1 m/s below its
    start) until the car's speed first reaches the lowest reference speed + 0.5 m/s; NaN when
    the reference does not brake or the car never slows that far."""
    if not len(v_ref) or float(np.min(v_ref)) > float(v_ref[0]) - 0.1:
        return math.nan
    start = int(np.argmax(v_ref < v_ref[0] - 0.1))
    slow = np.flatnonzero(vx[start:] <= float(np.min(v_ref)) + 0.5)
    return float(x[start + slow[0]] - x[start]) if slow.size else math.nan


def limit_metrics(log: Any, track_m: float, radius_m: float,
                  nearest: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
                  ) -> dict[str, Any]:
    """The module docstring's metrics of a :class:`~fourws_bringup.core.closed_loop.
    ClosedLoopLog` (``track_m``, ``radius_m``: the allocator's B and R; ``nearest``: the
    log's ``metrics.path_nearest`` when the caller has it)."""
    s, ref = log.state, log.reference
    vx = np.asarray(s["vx"], float)
    mu_w = np.asarray(s["mu"], float)          # (n, 4); a run that ended at once has none
    mu = np.mean(mu_w.reshape(len(vx), -1), axis=1) if len(vx) else np.zeros(0)
    beta = np.degrees(np.abs(np.asarray(s["sideslip"], float)))
    r = np.abs(np.asarray(s["yaw_rate"], float))
    with np.errstate(divide="ignore", invalid="ignore"):
        r_lim = np.where(vx > 1.0, mu * G / np.maximum(vx, 1.0), np.nan)
        ratio = r / r_lim
    e_y, _, idx = path_nearest(ref, s["x"], s["y"], s["yaw"]) if nearest is None else nearest
    e_y = np.abs(e_y)
    v_ref = np.asarray(ref.speed, float)[idx]
    kappa = np.abs(np.asarray(ref.curvature, float))
    demand = kappa * np.asarray(ref.speed, float) ** 2
    mu_road = float(np.median(mu)) if len(mu) else math.nan
    mz_cmd = np.asarray(log.mpc["yaw_moment"], float)
    wheels = np.asarray(log.wheel_torque_cmd_nm, float).reshape(-1, 4)
    unmet_mz = np.abs(mz_cmd - delivered_yaw_moment(wheels, track_m, radius_m))
    unmet_fx = np.abs(np.asarray(log.drive_torque_nm, float) - wheels.sum(axis=1)) / radius_m
    max_beta = float(np.max(beta)) if len(beta) else math.nan
    spin = bool(max_beta >= SPIN_SIDESLIP_DEG or "sideslip" in str(log.reason))
    xs, ys = (np.asarray(s[k], float) for k in ("x", "y"))
    width = float(getattr(log, "vehicle_width_m", VEHICLE_WIDTH_M))   # the course's car
    cones = cone_excess(tuple(log.lanes), xs, ys, width) if log.lanes else math.nan
    lane = (cones > 0.0 if log.lanes else bool(len(e_y) and float(np.max(e_y))
                                                > lane_free_m(width))
            ) or "lateral" in str(log.reason)

    def peak(a: np.ndarray) -> float:
        a = a[np.isfinite(a)]
        return float(np.max(a)) if a.size else math.nan

    return {
        "demand_mug": float(np.max(demand)) / (mu_road * G) if mu_road > 0 else math.nan,
        "yaw_rate_ratio": peak(ratio),
        "spin": spin,
        "lane_violation": bool(lane),
        "cone_excess_m": cones,
        "braking_distance_m": braking_distance(xs, vx, v_ref),
        "speed_error_max_mps": peak(np.abs(vx - v_ref)) if len(v_ref) else math.nan,
        "unmet_fx_max_n": peak(unmet_fx),
        "unmet_mz_max_nm": peak(unmet_mz),
        "completed_clean": bool(log.completed and not spin and not lane),
    }
