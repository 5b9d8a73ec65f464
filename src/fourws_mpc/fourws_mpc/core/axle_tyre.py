"""Gives one axle's Magic Formula lateral force and its slopes, for the friction-aware model.

The friction-aware model's axle tyre (docs/mpc.md, "Friction-aware prediction"). For an axle
with cornering stiffness K (N/rad, both tyres) and peak force D = μ F_z ε (N)::

    F(α) = D sin(C atan(z − E (z − atan z))),   z = B α,   B = K / (C D)        (MF, pure slip)

so F = K α at small α and |F| ≤ D. Its slopes::

    ∂F/∂α = K cos(C atan φ) (1 − E + E/(1 + z²)) / (1 + φ²),   φ = z − E (z − atan z)
    ∂F/∂D = g(z) − z g'(z),   g(z) = sin(C atan φ(z))       (B follows D)

Beyond the peak ∂F/∂α < 0: a prediction linearised there sees that more slip gives less
force (Falcone et al. 2007). F grows with D at any α (∂F/∂D ≥ 0), so a measured force
gives the road's μ by bisection (``grip``).
"""

from __future__ import annotations

import math

from numba import njit

#: lower bound on the peak force in the model (N): keeps B = K/(C D) finite
MIN_PEAK_N = 1.0


@njit(cache=True)
def _g(z: float, c: float, e: float) -> tuple[float, float]:
    """g(z) = sin(C atan φ) and g'(z)."""
    phi = z - e * (z - math.atan(z))
    ang = c * math.atan(phi)
    dphi = 1.0 - e + e / (1.0 + z * z)
    return math.sin(ang), math.cos(ang) * c * dphi / (1.0 + phi * phi)


@njit(cache=True)
def force(alpha: float, k: float, d: float, c: float, e: float
          ) -> tuple[float, float, float]:
    """(F, ∂F/∂α, ∂F/∂D) of the axle at slip angle ``alpha`` (rad), stiffness ``k`` (N/rad),
    peak ``d`` (N, floored at :data:`MIN_PEAK_N`), shape ``c`` and curvature ``e`` (compiled)."""
    d = max(d, MIN_PEAK_N)
    b = k / (c * d)
    z = b * alpha
    g, dg = _g(z, c, e)
    return d * g, d * dg * b, g - z * dg


@njit(cache=True)
def stiffness_at_load(k_static: float, fz_static: float, fz: float, peak_load: float
                      ) -> float:
    """A tyre's cornering stiffness (N/rad) at load ``fz`` (N), from its value ``k_static`` at
    ``fz_static``: K(F_z) ∝ sin(2 atan(F_z/F_k)), F_k = p_Ky2 F_z0 the load where it peaks
    (MF 5.2 load sensitivity, the plant's law; docs/plant.md, "Tyres")."""
    law = math.sin(2.0 * math.atan(max(fz, 0.0) / peak_load))
    return k_static * law / math.sin(2.0 * math.atan(fz_static / peak_load))
