"""The friction-aware model's axle tyre: Magic Formula lateral force of one axle, its slopes,
and its inverse for the peak (docs/mpc.md, "Friction-aware prediction").

For an axle with cornering stiffness K (N/rad, both tyres) and peak force D = μ F_z ε (N)::

    F(α) = D sin(C atan(z − E (z − atan z))),   z = B α,   B = K / (C D)        (MF, pure slip)

so F = K α at small α and |F| ≤ D. Its slopes:

    ∂F/∂α = K cos(C atan φ) (1 − E + E/(1 + z²)) / (1 + φ²),   φ = z − E (z − atan z)
    ∂F/∂D = g(z) − z g'(z),   g(z) = sin(C atan φ(z))       (B follows D)

Beyond the peak ∂F/∂α < 0: a prediction linearised there sees that more slip gives less
force (Falcone et al. 2007). :func:`peak_from_force` inverts F for D given a measured (α, F).
"""

from __future__ import annotations

import math

#: lower bound on the peak force in the model (N): keeps B = K/(C D) finite
MIN_PEAK_N = 1.0


def _g(z: float, c: float, e: float) -> tuple[float, float]:
    """g(z) = sin(C atan φ) and g'(z)."""
    phi = z - e * (z - math.atan(z))
    ang = c * math.atan(phi)
    dphi = 1.0 - e + e / (1.0 + z * z)
    return math.sin(ang), math.cos(ang) * c * dphi / (1.0 + phi * phi)


def force(alpha: float, k: float, d: float, c: float, e: float
          ) -> tuple[float, float, float]:
    """(F, ∂F/∂α, ∂F/∂D) of the axle at slip angle ``alpha`` (rad), stiffness ``k`` (N/rad),
    peak ``d`` (N, floored at :data:`MIN_PEAK_N`), shape ``c`` and curvature ``e``."""
    d = max(d, MIN_PEAK_N)
    b = k / (c * d)
    z = b * alpha
    g, dg = _g(z, c, e)
    return d * g, d * dg * b, g - z * dg


def peak_from_force(alpha: float, f: float, k: float, c: float, e: float,
                    min_deficit: float) -> float | None:
    """The peak D for which F(α) = f, or None when (α, f) says nothing of the peak.

    Evidence needs |f| below the linear K|α| by a clear margin, K|α| − |f| ≥ ``min_deficit``
    (N), with f and α of one sign. Then g(z)/z = C |f|/(K|α|) is solved for z (g(z)/z falls
    from C at z = 0) and D = K|α|/(C z). Past the peak's flat top the answer is |f|/g(z)."""
    if alpha == 0.0 or f * alpha <= 0.0:
        return None
    ka = k * abs(alpha)
    if ka - abs(f) < min_deficit:
        return None
    target = c * abs(f) / ka
    lo, hi = 1e-9, 50.0
    if _g(hi, c, e)[0] / hi > target:
        return abs(f) / max(_g(hi, c, e)[0], 1e-9)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if _g(mid, c, e)[0] / mid > target:
            lo = mid
        else:
            hi = mid
    return ka / (c * 0.5 * (lo + hi))
