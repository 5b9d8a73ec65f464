"""Gives the Magic Formula's peak: the one fact the plant's tyre and the MPC's axle share.

For F = D sin(C atan(u − E(u − atan u))), u = B α (Pacejka, *Tyre and Vehicle Dynamics*, 3rd
ed., 2012, eq. 4.49, pure slip), the force peaks where C atan φ(u) = π/2, φ(u) = u − E(u −
atan u) (docs/plant.md, "Tyres"; docs/mpc.md, "Friction-aware prediction").
"""

from __future__ import annotations

import math


def _phi(u: float, e: float) -> float:
    return u - e * (u - math.atan(u))


def peak_argument(shape_c: float, curvature_e: float) -> float:
    """u* = B α at the Magic Formula's peak: the root of C atan φ(u) = π/2 (bisection).

    Requires 1 < C < 2 and E < 1 (φ then grows without bound and the root is unique); else
    ``ValueError``.
    """
    if not 1.0 < shape_c < 2.0:
        raise ValueError(f"Magic Formula shape factor C must be in (1, 2), got {shape_c}")
    if not curvature_e < 1.0:
        raise ValueError(f"Magic Formula curvature factor E must be < 1, got {curvature_e}")
    target = math.tan(math.pi / (2.0 * shape_c))
    lo, hi = 0.0, 1.0
    while _phi(hi, curvature_e) < target:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if _phi(mid, curvature_e) < target:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
