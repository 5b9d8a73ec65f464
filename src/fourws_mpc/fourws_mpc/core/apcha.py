"""Adapts the prediction and control horizons (APCHA), eq. (7)-(15).

Indicators (docs/mpc.md, "APCHA")::

    e_s = |e_Y| / e_Y,max + λ |e_φ| / e_φ,max,     λ ∈ (0, 1)                 # eq. (7)
    k_e = |e_s(k) − e_s(k−1)| / T                                               # eq. (8)
    k_u = ‖D_Δu⁻¹ Δu‖_∞,  D_Δu = diag(Δδf,max, Δδr,max, ΔMz,max)                # eq. (9)-(11)

(eq. (12) repeats eq. (9).) Δu is the last *applied* increment u(k−1) − u(k−2) (the increment
of step k is the QP's output); k_e = 0 on the first step.

Prediction horizon, eq. (13) (e_s = 2ε1, left open by the paper, goes to the middle branch)::

    N_p^t = N_p,max − ΔN_p                 if e_s > 2ε1
            ⌊(N_p,max + N_p,min)/2⌋        if ε1 < e_s ≤ 2ε1
            N_p,min + ΔN_p                 if e_s ≤ ε1

Control horizon, eq. (14), first matching branch wins::

    N_c^t = N_c^i + ΔN_c   if k_e > ε2;   N_c^i − ΔN_c   if k_u > ε3;   N_c^i otherwise

Clamps, eq. (15)::

    N_p = clamp(N_p, N_p,min, N_p,max);  N_c = clamp(N_c^t, N_c,min, N_c,max);
    N_c = max(⌊N_p/3⌋, min(N_c, ⌊N_p/2⌋))

Readings (the paper is not self-consistent here): with ``np_rate_limit`` N_p moves from its
previous value towards N_p^t by at most ΔN_p per period (the "step size constraint" of section
3.1). The printed N_c^i = ⌊N_p^t/3⌋ contradicts the paper's baseline N_c = 6 at N_p = 12 and
its N_c 6 → 10 at N_p = 20; with ``nc_base = "previous"`` (default) N_c^i is the previous N_c
(starting at the baseline), so ΔN_c is a per-period step and ⌊N_p/3⌋ acts through the clamp of
eq. (15). ``nc_base = "np_third"`` is the literal eq. (14).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ApchaParams:
    """Constants of eq. (7)-(15) (SI: e_phi_max in rad, du_max in rad, rad, N·m)."""

    np_min: int = 10
    np_max: int = 30
    np_step: int = 2
    nc_min: int = 3
    nc_max: int = 10
    nc_step: int = 1
    eps1: float = 0.2
    eps2: float = 0.5
    eps3: float = 0.3
    lam: float = 0.5
    e_y_max: float = 0.5
    e_phi_max: float = math.radians(8.0)
    du_max: tuple[float, float, float] = (math.radians(0.8), math.radians(0.6), 300.0)
    dt_s: float = 0.01
    np_rate_limit: bool = True
    nc_base: str = "previous"


@dataclass(frozen=True, slots=True)
class ApchaResult:
    """Horizons for this step and the indicators that chose them."""

    n_p: int
    n_c: int
    e_s: float
    k_e: float
    k_u: float
    np_target: int
    nc_target: int


def integrated_error(e_y: float, e_phi: float, p: ApchaParams) -> float:
    """e_s of eq. (7) from e_Y (m) and e_φ (rad)."""
    return abs(e_y) / p.e_y_max + p.lam * abs(e_phi) / p.e_phi_max


def input_rate(du: np.ndarray, p: ApchaParams) -> float:
    """k_u of eq. (9): ‖D_Δu⁻¹ Δu‖_∞ for Δu = [Δδf, Δδr, ΔMz] (rad, rad, N·m)."""
    return max(abs(d) / m for d, m in zip(np.asarray(du, float).tolist(), p.du_max,
                                          strict=True))


def np_target(e_s: float, p: ApchaParams) -> int:
    """N_p^t of eq. (13)."""
    if e_s > 2.0 * p.eps1:
        return p.np_max - p.np_step
    if e_s > p.eps1:
        return (p.np_max + p.np_min) // 2
    return p.np_min + p.np_step


def clamp_nc(n_c: int, n_p: int) -> int:
    """The last clamp of eq. (15): N_c within [⌊N_p/3⌋, ⌊N_p/2⌋] (the lower bound wins)."""
    return max(n_p // 3, min(n_c, n_p // 2))


def apcha(e_s: float, e_s_prev: float | None, du_prev: np.ndarray,
          np_prev: int, nc_prev: int, p: ApchaParams) -> ApchaResult:
    """One APCHA update, eq. (8)-(15).

    e_s: this step's integrated error (eq. 7); e_s_prev: the previous one (None on the first
    step → k_e = 0); du_prev (3,): last applied increment; np_prev, nc_prev: horizons of the
    previous step (the baseline on the first step).
    """
    k_e = 0.0 if e_s_prev is None else abs(e_s - e_s_prev) / p.dt_s
    k_u = input_rate(du_prev, p)
    npt = np_target(e_s, p)
    n_p = npt
    if p.np_rate_limit:
        n_p = np_prev + max(-p.np_step, min(p.np_step, npt - np_prev))
    n_p = max(p.np_min, min(n_p, p.np_max))

    nc_i = nc_prev if p.nc_base == "previous" else npt // 3
    if k_e > p.eps2:
        nct = nc_i + p.nc_step
    elif k_u > p.eps3:
        nct = nc_i - p.nc_step
    else:
        nct = nc_i
    n_c = clamp_nc(max(p.nc_min, min(nct, p.nc_max)), n_p)
    return ApchaResult(int(n_p), int(n_c), float(e_s), float(k_e), float(k_u), int(npt),
                       int(nct))
