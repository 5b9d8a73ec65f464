"""Tracking metrics of a run, the metrics.json keys (docs/graph.md, "Runs"), from per-step arrays.

Lateral and heading errors are measured against the reference path geometry by
:func:`path_errors` (:func:`path_nearest`) — nearest point with projection between samples,
signed lateral offset (left positive) and heading error wrapped to (−π, π]
(``fourws_mpc.core.reference``) — so the in-process closed loop and a recorded bag give the
same numbers from the same poses.

Definitions (n steps, errors e_k)::

    max_abs = max |e_k|,   rmse = √(Σ e_k² / n),   mae = Σ |e_k| / n

Angles are reported in degrees (keys ``*_deg``). ``mpc_solve_ms_p50``/``_p99`` are the 50th
and 99th percentiles (linear interpolation) of the per-step MPC solve times; NaN when no time
was measured.

Allocation audit (:func:`allocate_series`, :func:`rear_load_ratio_share`,
:func:`tyre_usage`): the lower layer re-run on a run's recorded demands and wheel states.
With B_f = B_r, eq. (27) fixes each side's torque sum, S_L = T/2 − M_z r/B and
S_R = T/2 + M_z r/B; eq. (26)-(31) only chooses the front/rear split of each sum, giving the
rear wheel the share w = c_r²/(c_f² + c_r²), c_i = μ_i F_zi, where the rule-based baseline
gives 1/2. Tyre usage is eq. (25), η_i = √(F_xi² + F_yi²)/(μ_i F_zi).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from fourws_common.wheels import Wheel
from fourws_mpc.core.reference import Reference
from fourws_torque_alloc.core.allocation import AllocatorConfig, allocate

METRIC_KEYS = (
    "max_abs_lateral_error_m", "rmse_lateral_error_m", "mae_lateral_error_m",
    "max_abs_heading_error_deg", "rmse_heading_error_deg",
    "max_abs_sideslip_deg", "rmse_sideslip_deg",
    "mpc_solve_ms_p50", "mpc_solve_ms_p99",
)


def reference_from_arrays(x: Sequence[float], y: Sequence[float], yaw: Sequence[float],
                          curvature: Sequence[float] | None = None,
                          speed: Sequence[float] | None = None) -> Reference:
    """A :class:`Reference` from path arrays (as in a ReferenceTrajectory message)."""
    n = len(x)
    return Reference.from_arrays(x, y, yaw,
                                 np.zeros(n) if curvature is None else curvature,
                                 np.zeros(n) if speed is None else speed)


def path_errors(ref: Reference, x: Sequence[float], y: Sequence[float],
                yaw: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Lateral (m, left +) and heading (rad) errors of poses (n,) against the path (n,), (n,):
    the first two of :func:`path_nearest`."""
    e_y, e_phi, _ = path_nearest(ref, x, y, yaw)
    return e_y, e_phi


def path_nearest(ref: Reference, x: Sequence[float], y: Sequence[float],
                 yaw: Sequence[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(e_Y (m, left +), e_φ (rad), index of the nearest segment) of poses (n,) each.

    Consecutive poses are searched in a window around the previous nearest index (global
    search on the first pose or when the window's edge is hit).
    """
    xs, ys, yaws = (np.asarray(a, float).reshape(-1) for a in (x, y, yaw))
    e_y = np.empty(len(xs))
    e_phi = np.empty(len(xs))
    index = np.empty(len(xs), dtype=np.int64)
    hint: int | None = None
    for k in range(len(xs)):
        e = ref.errors(float(xs[k]), float(ys[k]), float(yaws[k]), hint)
        hint = index[k] = e.near.index
        e_y[k] = e.lateral_error
        e_phi[k] = e.heading_error
    return e_y, e_phi, index


def _stats(e: np.ndarray) -> tuple[float, float, float]:
    if e.size == 0:
        return math.nan, math.nan, math.nan
    a = np.abs(e)
    return float(a.max()), float(np.sqrt(np.mean(e * e))), float(a.mean())


def compute_metrics(lateral_error: Sequence[float], heading_error: Sequence[float],
                    sideslip: Sequence[float],
                    solve_ms: Sequence[float] | None = None) -> dict[str, float]:
    """The nine metric values of :data:`METRIC_KEYS` from per-step arrays (SI in, report out).

    lateral_error (m), heading_error (rad), sideslip (rad), solve_ms (ms, optional).
    """
    ey = np.asarray(lateral_error, float).reshape(-1)
    ephi = np.degrees(np.asarray(heading_error, float).reshape(-1))
    beta = np.degrees(np.asarray(sideslip, float).reshape(-1))
    m_ey, r_ey, a_ey = _stats(ey)
    m_ph, r_ph, _ = _stats(ephi)
    m_b, r_b, _ = _stats(beta)
    t = np.asarray([] if solve_ms is None else solve_ms, float).reshape(-1)
    t = t[np.isfinite(t)]
    p50 = float(np.percentile(t, 50)) if t.size else math.nan
    p99 = float(np.percentile(t, 99)) if t.size else math.nan
    return {
        "max_abs_lateral_error_m": m_ey, "rmse_lateral_error_m": r_ey,
        "mae_lateral_error_m": a_ey,
        "max_abs_heading_error_deg": m_ph, "rmse_heading_error_deg": r_ph,
        "max_abs_sideslip_deg": m_b, "rmse_sideslip_deg": r_b,
        "mpc_solve_ms_p50": p50, "mpc_solve_ms_p99": p99,
    }


def run_metrics(ref: Reference, t: Sequence[float], x: Sequence[float], y: Sequence[float],
                yaw: Sequence[float], vx: Sequence[float], vy: Sequence[float],
                sideslip: Sequence[float] | None = None,
                solve_ms: Sequence[float] | None = None,
                errors: tuple[np.ndarray, np.ndarray] | None = None) -> dict[str, float]:
    """Metrics of a run from its poses: errors by :func:`path_errors` (or ``errors``, the
    (e_Y, e_φ) the caller already has from them), sideslip as recorded (or atan2(vy, vx)
    when not given). Also returns ``steps`` and ``sim_time_s``."""
    e_y, e_phi = path_errors(ref, x, y, yaw) if errors is None else errors
    beta = (np.arctan2(np.asarray(vy, float), np.asarray(vx, float)) if sideslip is None
            else np.asarray(sideslip, float))
    out: dict[str, float] = compute_metrics(e_y, e_phi, beta, solve_ms)
    tt = np.asarray(t, float)
    out["steps"] = int(tt.size)
    out["sim_time_s"] = float(tt[-1] - tt[0]) if tt.size else 0.0
    return out


def allocate_series(method: str, torque_nm: Sequence[float], yaw_moment_nm: Sequence[float],
                    fz_n: np.ndarray, fy_n: np.ndarray, mu: np.ndarray,
                    cfg: AllocatorConfig) -> np.ndarray:
    """Wheel torques (n, 4) N·m, FL FR RL RR, that allocation ``method`` gives for each step's
    total torque and yaw moment (n,) N·m and wheel loads, lateral forces (n, 4) N and μ (n, 4).
    Raises ``ValueError`` as the allocator core does on a bad step."""
    t = np.asarray(torque_nm, float).reshape(-1)
    mz = np.asarray(yaw_moment_nm, float).reshape(-1)
    fz, fy, m = (np.asarray(a, float).reshape(-1, 4) for a in (fz_n, fy_n, mu))
    out = np.empty((t.size, 4))
    for k in range(t.size):
        out[k] = allocate(method, float(t[k]), float(mz[k]), fz[k], fy[k], m[k],
                          cfg).torque_nm
    return out


def rear_load_ratio_share(fz_n: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Share of each side's torque sum that eq. (26)-(31) gives the rear wheel, (n, 2) for
    the left and right side: c_r²/(c_f² + c_r²) with c_i = μ_i F_zi (NaN where both are 0)."""
    c = np.asarray(mu, float).reshape(-1, 4) * np.asarray(fz_n, float).reshape(-1, 4)
    c2 = c * c
    front = c2[:, [Wheel.FL, Wheel.FR]]
    rear = c2[:, [Wheel.RL, Wheel.RR]]
    total = front + rear
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0.0, rear / total, np.nan)


def tyre_usage(fx_n: np.ndarray, fy_n: np.ndarray, fz_n: np.ndarray,
               mu: np.ndarray) -> np.ndarray:
    """Tyre load ratio η (n, 4) of eq. (25); inf for a loaded tyre on μ = 0, NaN in the air."""
    fx, fy, fz, m = (np.asarray(a, float).reshape(-1, 4) for a in (fx_n, fy_n, fz_n, mu))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.hypot(fx, fy) / (m * np.maximum(fz, 0.0))
