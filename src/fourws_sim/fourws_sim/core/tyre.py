"""Computes Magic Formula tyre forces: pure slip, and combined slip by a friction ellipse.

Pure slip (Pacejka's Magic Formula, shifts and camber omitted; docs/plant.md, "Tyres")::

    F0(x) = D sin(C atan(B x − E (B x − atan(B x))))
    D = μ F_z λ(F_z)            peak force: the road's adhesion coefficient μ times the load,
    λ = min(1, 1 + p_D2 df_z)   times the friction load sensitivity (MF: p_Dy2 df_z with
                                df_z = (F_z − F_z0)/F_z0; p_D2 ≤ 0), capped at 1
    B = K / (C D)               so that dF0/dx at x = 0 is the slip stiffness K

with x = κ (longitudinal slip ratio) or α (slip angle, rad). The slip stiffnesses do not
depend on μ (MF convention: μ scales D, and B follows so that B·C·D = K):

    K_α(F_z) = p_Ky1 F_z0 sin(2 atan(F_z / (p_Ky2 F_z0)))      cornering stiffness, N/rad
                                                              (MF 5.2 load sensitivity)
    K_κ(F_z) = c_κ F_z                                          longitudinal slip stiffness, N

p_Ky1 differs between the front and the rear tyres (``VehicleParams``); everything else is
shared. The cap λ ≤ 1 departs from MF (where a tyre lighter than F_z0 would get a friction
coefficient above p_Dy1): no tyre exceeds μ F_z, the bound the torque allocation of eq. 25-31
assumes (the default p_D2 = 0 keeps D = μ F_z exactly; see the car file). Because B·x_peak is
a constant u* of C and E alone (the root of C atan(u − E(u − atan u)) = π/2), the peak slips
are x_peak = u* C D / K: they scale with μ and with F_z / K(F_z).

Combined slip: normalised-slip friction ellipse (the "similarity" idea, Pacejka, *Tire and
Vehicle Dynamics*, 3rd ed., 2012, ch. 4), not MF's G functions: with μ-scaled peaks their
fixed coefficients let the resultant exceed μ F_z at low μ by 10 % or more. With
s_x = κ/κ_peak, s_y = α/α_peak and ρ = √(s_x² + s_y²)::

    F_x = (s_x/ρ) F0_x(ρ κ_peak),      F_y = (s_y/ρ) F0_y(ρ α_peak)

Properties (each one is tested): pure slip is reproduced exactly; at small slip
F_x = K_κ κ and F_y = K_α α (the linear stiffnesses are not reduced by the other slip); the
resultant never exceeds D ≤ μ F_z, since F0 ≤ D and (s_x/ρ)² + (s_y/ρ)² = 1.

Slips (wheel frame, x along the wheel's heading, y to its left)::

    κ = (ω R − v_x) / max(|v_x|, v_min)
    α = −atan(v_y / max(|v_x|, v_min))

so that F_y > 0 (to the left) when the contact point slides to the right (ISO 8855; with
eq. (1) of the paper α_f = δ_f − (v_y + a r)/v_x). The floor v_min keeps both finite at
standstill and bounds the wheel-spin eigenvalue −R² K_κ / (I_w v_min) (see ``vehicle.py``).

:func:`forces` (numpy, vectorised over any shape, for analysis and tests) and
:func:`forces_scalar` (plain floats, for the plain-float derivative function) compute the same
equations (a unit test checks); the simulator runs a compiled twin of :func:`forces_scalar`
(``model_jit.tyre_forces``, checked against it by another test).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fourws_common.magic_formula import peak_argument


@dataclass(frozen=True)
class TyreCoefficients:
    """Coefficients of one tyre (``cornering_coeff`` may be an array, one per wheel).

    nominal_load_n        F_z0, N
    cornering_coeff       p_Ky1, 1 (K_α peaks at p_Ky1 F_z0 when F_z = p_Ky2 F_z0)
    cornering_load_factor p_Ky2, 1
    long_stiffness_per_load  c_κ = K_κ / F_z, 1
    friction_load_sensitivity  p_D2 ≤ 0, 1
    shape_lat, curvature_lat    C_y, E_y
    shape_long, curvature_long  C_x, E_x
    """

    nominal_load_n: float
    cornering_coeff: float | np.ndarray
    cornering_load_factor: float
    long_stiffness_per_load: float
    friction_load_sensitivity: float
    shape_lat: float
    curvature_lat: float
    shape_long: float
    curvature_long: float
    peak_u_lat: float = field(init=False)
    peak_u_long: float = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "peak_u_lat", peak_argument(self.shape_lat, self.curvature_lat))
        object.__setattr__(
            self, "peak_u_long", peak_argument(self.shape_long, self.curvature_long)
        )

    def scalar_constants(self, cornering_coeff: float) -> tuple[float, ...]:
        """The tuple :func:`forces_scalar` takes, for one wheel's p_Ky1."""
        return (
            float(cornering_coeff) * self.nominal_load_n,
            1.0 / (self.cornering_load_factor * self.nominal_load_n),
            self.friction_load_sensitivity,
            1.0 / self.nominal_load_n,
            self.long_stiffness_per_load,
            self.shape_lat,
            self.curvature_lat,
            self.peak_u_lat,
            self.shape_long,
            self.curvature_long,
            self.peak_u_long,
        )


def cornering_stiffness(fz: float | np.ndarray, c: TyreCoefficients) -> float | np.ndarray:
    """K_α(F_z) = p_Ky1 F_z0 sin(2 atan(F_z/(p_Ky2 F_z0))), N/rad; F_z in N (≥ 0)."""
    fz = np.maximum(fz, 0.0)
    return c.cornering_coeff * c.nominal_load_n * np.sin(
        2.0 * np.arctan(fz / (c.cornering_load_factor * c.nominal_load_n))
    )


def friction_factor(fz: float | np.ndarray, c: TyreCoefficients) -> float | np.ndarray:
    """λ(F_z) = min(1, 1 + p_D2 (F_z − F_z0)/F_z0), floored at 0.1: the tyre's peak friction
    over the road's μ."""
    dfz = (np.maximum(fz, 0.0) - c.nominal_load_n) / c.nominal_load_n
    return np.clip(1.0 + c.friction_load_sensitivity * dfz, 0.1, 1.0)


def longitudinal_stiffness(fz: float | np.ndarray, c: TyreCoefficients) -> float | np.ndarray:
    """K_κ(F_z) = c_κ F_z, N per unit slip ratio."""
    return c.long_stiffness_per_load * np.maximum(fz, 0.0)


def slips(
    vx_wheel: np.ndarray, vy_wheel: np.ndarray, omega: np.ndarray, radius_m: float, v_min: float
) -> tuple[np.ndarray, np.ndarray]:
    """Slip ratio κ and slip angle α (rad) from the contact-point velocity in the wheel frame
    (m/s) and the spin rate ω (rad/s); denominators floored at ``v_min`` (m/s)."""
    den = np.maximum(np.abs(vx_wheel), v_min)
    kappa = (omega * radius_m - vx_wheel) / den
    alpha = -np.arctan(vy_wheel / den)
    return kappa, alpha


def pure_force(
    x: np.ndarray, d: np.ndarray, stiffness: np.ndarray, shape_c: float, curvature_e: float
) -> np.ndarray:
    """Magic Formula F0(x) = D sin(C atan(Bx − E(Bx − atan Bx))), B = K/(C D); D = 0 → 0."""
    d = np.asarray(d, dtype=float)
    safe_d = np.where(d > 0.0, d, 1.0)
    bx = np.asarray(stiffness, dtype=float) * x / (shape_c * safe_d)
    arg = bx - curvature_e * (bx - np.arctan(bx))
    return np.where(d > 0.0, d * np.sin(shape_c * np.arctan(arg)), 0.0)


def forces(
    kappa: np.ndarray, alpha: np.ndarray, fz: np.ndarray, mu: np.ndarray, c: TyreCoefficients
) -> tuple[np.ndarray, np.ndarray]:
    """Combined-slip tyre forces (F_x, F_y), N, in the wheel frame; vectorised, any shape.

    κ slip ratio, α slip angle (rad), F_z load (N, clipped at 0), μ road adhesion.
    """
    kappa = np.asarray(kappa, dtype=float)
    alpha = np.asarray(alpha, dtype=float)
    fz = np.maximum(np.asarray(fz, dtype=float), 0.0)
    d = np.asarray(mu, dtype=float) * fz * friction_factor(fz, c)
    k_a = cornering_stiffness(fz, c)
    k_k = longitudinal_stiffness(fz, c)
    ok = (d > 0.0) & (k_a > 0.0) & (k_k > 0.0)
    safe = np.where(ok, 1.0, 0.0)
    d_s = np.where(ok, d, 1.0)
    kappa_pk = c.peak_u_long * c.shape_long * d_s / np.where(ok, k_k, 1.0)
    alpha_pk = c.peak_u_lat * c.shape_lat * d_s / np.where(ok, k_a, 1.0)
    sx = kappa / kappa_pk
    sy = alpha / alpha_pk
    rho = np.hypot(sx, sy)
    small = rho < 1e-12
    rho_s = np.where(small, 1.0, rho)

    def shape_over_rho(u_pk: float, shape_c: float, e: float) -> np.ndarray:
        u = rho * u_pk
        arg = u - e * (u - np.arctan(u))
        return np.where(small, shape_c * u_pk, np.sin(shape_c * np.arctan(arg)) / rho_s)

    gx = shape_over_rho(c.peak_u_long, c.shape_long, c.curvature_long)
    gy = shape_over_rho(c.peak_u_lat, c.shape_lat, c.curvature_lat)
    return safe * d_s * sx * gx, safe * d_s * sy * gy


def forces_scalar(
    kappa: float, alpha: float, fz: float, mu: float, k: tuple[float, ...]
) -> tuple[float, float]:
    """Plain-float twin of :func:`forces` for one wheel; ``k`` from
    :meth:`TyreCoefficients.scalar_constants`."""
    ky1_fz0, inv_ky2_fz0, p_d2, inv_fz0, c_kx, cy, ey, uy, cx, ex, ux = k
    lam = 1.0 + p_d2 * (fz * inv_fz0 - 1.0)
    lam = 1.0 if lam > 1.0 else (0.1 if lam < 0.1 else lam)
    d = mu * fz * lam
    if d <= 0.0:
        return 0.0, 0.0
    k_a = ky1_fz0 * math.sin(2.0 * math.atan(fz * inv_ky2_fz0))
    sx = kappa * c_kx * fz / (ux * cx * d)
    sy = alpha * k_a / (uy * cy * d)
    rho = math.sqrt(sx * sx + sy * sy)
    if rho < 1e-12:
        return d * sx * cx * ux, d * sy * cy * uy
    u = rho * ux
    gx = math.sin(cx * math.atan(u - ex * (u - math.atan(u)))) / rho
    u = rho * uy
    gy = math.sin(cy * math.atan(u - ey * (u - math.atan(u)))) / rho
    return d * sx * gx, d * sy * gy
