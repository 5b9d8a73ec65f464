"""Estimates the road's grip as the MPC sees it: a μ estimate and the envelope it gives.

Part of the friction-aware prediction (docs/mpc.md, "Friction-aware prediction").

**Estimate.** When the state carries μ (the idealised world: the plant's truth) it is used.
Otherwise μ̂ comes from the transient slips α̂' of the slip observer and a_y. The car's lateral
force is m a_y; the four tyres' Magic Formula forces Σ_i F(α̂'_i; K_i, μ F_z,i ε), each wheel
at its axle's α̂', grow with μ. The loads F_z,i are the quasi-static transfer of the measured
a_x, a_y (``fourws_common.load_transfer``) and each K_i the tyre's stiffness at its load
(:func:`axle_tyre.stiffness_at_load`): the outer wheel gains less stiffness than the inner
one loses, so at 0.63 g the front axle is 12 % softer than at static load, a deficit that static
loads would take for the peak. When the linear tyres' sum Σ K_i α̂'_i exceeds |m a_y| by at
least ``mu_evidence_deficit`` m g, the tyres have shown their peak and the μ that matches
m a_y is the evidence (bisection). Evidence is taken only while |a_x| ≤
``mu_evidence_max_ax`` μ̂ g (0.31: the friction ellipse then takes at most 5 % of the lateral
grip, half the evidence margin); else μ̂ holds, since the split of the longitudinal forces
between the wheels is not known. And only while the linear tyres ask for at least
``mu_evidence_min_ask`` (0.3) of the grip the prior allows, |Σ K_i α̂'_i| ≥ 0.3 μ_prior m g:
below half its peak a Magic Formula tyre is within 3 % of linear, so a deficit at a smaller
ask is the slip observer's error (its lateral-velocity input), not the peak; a road down to
0.12 μ_prior still shows at its peak slip, where the ask is u*·C μ m g = 2.41 μ m g
(studies/grip_estimate). Below ``mu_evidence_min_speed_mps`` (10 m/s) μ̂ holds (neither
evidence nor the prior; a non-finite speed too): the slip error
of a lateral-velocity error e is e/v_x, and at 5.5 m/s the realistic condition's 3σ (0.1 m/s)
gives 1.0°, past the 0.87° at which the linear tyres ask 0.3 of the prior 0.8's grip; at
10 m/s it gives 0.57°. μ̂ follows falling evidence with ``mu_fall_time_s``, rising evidence with
``mu_rise_time_s``, and without evidence returns to the prior ``mu_default`` with
``mu_rise_time_s``. μ̂ is never below the grip in use, √(a_x² + a_y²)/g, and is clamped to
[``mu_floor``, ``mu_ceiling``]; a clamp is flagged.

**Envelope** (Beal and Gerdes 2013), from μ̂:

* yaw rate |r| ≤ ``yaw_rate_mu_factor`` μ̂ g / v_x;
* sideslip |β| ≤ α_peak,r + b r_max / v_x, with α_peak,r the rear axle's peak slip angle
  (``max_sideslip_deg`` stays the upper cap);
* steer: each axle's kinematic slip at the current state within its peak slip
  (:func:`steer_window`), since a steer beyond it only lowers the force;
* yaw moment |M_z| ≤ (B/2) μ̂ m g (√(1 − η_y²) − |a_x|/(μ̂ g)): the longitudinal grip the
  wheels have left at the lateral use η_y = max |F(α̂')|/D of the two axles (friction ellipse).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from fourws_common.magic_formula import peak_argument
from fourws_mpc.core.axle_tyre import force
from fourws_mpc.core.friction_model import Grip, axle_loads, ellipse, tyre_sums
from fourws_mpc.core.model import (
    ModelParams,
    ModelTuple,
    StateIdx,
    as_vector,
    axle_directions,
    packed,
)
from fourws_mpc.core.relaxation_model import RelaxIdx

#: the μ range the evidence is searched in
MU_SEARCH = (0.02, 3.0)
#: flag values of :attr:`GripEstimate.note`
CLAMPED_LOW = "mu estimate clamped to mu_floor"
CLAMPED_HIGH = "mu estimate clamped to mu_ceiling"


@dataclass(frozen=True, slots=True)
class GripSettings:
    """The estimator's constants (``MpcConfig``'s keys of the same names)."""

    prior: float = 1.0
    floor: float = 0.1
    ceiling: float = 1.2
    evidence_deficit: float = 0.1
    evidence_max_ax: float = 0.31
    evidence_min_ask: float = 0.3
    evidence_min_speed: float = 0.0
    fall_time_s: float = 0.05
    rise_time_s: float = 1.0


@dataclass(frozen=True, slots=True)
class GripMemory:
    """What the estimator carries to the next step: μ̂."""

    mu: float


@dataclass(frozen=True, slots=True)
class GripEstimate:
    """μ̂ at one step, where it came from (state, evidence, prior) and any clamp note."""

    mu: float
    source: str
    note: str = ""


def _pole(dt_s: float, tau_s: float) -> float:
    return 1.0 - math.exp(-dt_s / tau_s)


@njit(cache=True)
def _matching_mu(zeta: np.ndarray, p: ModelTuple, eps: float, ax: float, ay: float,
                 f_abs: float) -> float:
    """The μ in :data:`MU_SEARCH` at which the four tyres' force magnitude equals ``f_abs``
    (40 bisections; the force grows with μ), compiled: the hot part of the evidence."""
    lo, hi = MU_SEARCH
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if abs(tyre_sums(zeta, p, mid, eps, ax, ay)[0]) < f_abs:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


class GripEstimator:
    """μ̂ of the module docstring. Pure: :meth:`estimate` returns the next memory."""

    def __init__(self, params: ModelParams, settings: GripSettings) -> None:
        self.p = params
        self.s = settings
        self._packed = packed(params)        # once: the kernels' form of the parameters

    def _clamp(self, mu: float) -> tuple[float, str]:
        if not math.isfinite(mu) or mu < self.s.floor:
            return self.s.floor, CLAMPED_LOW
        if mu > self.s.ceiling:
            return self.s.ceiling, CLAMPED_HIGH
        return mu, ""

    def evidence(self, zeta: np.ndarray, ax: float, ay: float, mz: float, mu_now: float
                 ) -> float | None:
        """The μ for which the tyres' forces at α̂' and the loads of a_x, a_y sum to m a_y,
        when the linear tyres ask for at least ``evidence_min_ask`` of the grip the prior
        allows and exceed m a_y by the margin (module docstring); else None."""
        p, z, packed_p = self.p, as_vector(zeta), self._packed
        f = p.mass_kg * ay
        weight = p.mass_kg * p.gravity_mps2
        _, linear = tyre_sums(z, packed_p, 1.0, 1.0, ax, ay)
        if (f * linear <= 0.0 or abs(linear) < self.s.evidence_min_ask * self.s.prior * weight
                or abs(linear) - abs(f) < self.s.evidence_deficit * weight):
            return None
        eps, _ = ellipse(mz, p, Grip(mu_now, ax))
        if abs(tyre_sums(z, packed_p, MU_SEARCH[1], eps, ax, ay)[0]) < abs(f):
            return None                       # no road explains it: not evidence
        return _matching_mu(z, packed_p, eps, ax, ay, abs(f))

    def estimate(self, zeta: np.ndarray, ax: float, ay: float, mz: float,
                 mu_state: float | None, memory: GripMemory | None, dt_s: float
                 ) -> tuple[GripEstimate, GripMemory]:
        """μ̂ at the measured ζ_t (with the observer's α̂'), the measured a_x, a_y (m/s²),
        the yaw moment last applied (N·m) and the state's μ (None: not measured)."""
        if mu_state is not None:
            mu, note = self._clamp(float(mu_state))
            return GripEstimate(mu, "state", note), GripMemory(mu)
        mu_prev = self.s.prior if memory is None else memory.mu
        held = (abs(ax) > self.s.evidence_max_ax * mu_prev * self.p.gravity_mps2
                or not zeta[StateIdx.VX] >= self.s.evidence_min_speed)
        ev = None if held else self.evidence(zeta, ax, ay, mz, mu_prev)
        if held:
            mu, source = mu_prev, "held"              # longitudinal use or slow: μ̂ holds
        else:
            target = self.s.prior if ev is None else ev
            tau = self.s.fall_time_s if target < mu_prev else self.s.rise_time_s
            mu = mu_prev + (_pole(dt_s, tau) if dt_s > 0.0 else 0.0) * (target - mu_prev)
            source = "prior" if ev is None else "evidence"
        used = math.hypot(ax, ay) / self.p.gravity_mps2
        mu, note = self._clamp(max(mu, used) if math.isfinite(used) else mu)
        return GripEstimate(mu, source, note), GripMemory(mu)


_peak_argument = functools.lru_cache(maxsize=8)(peak_argument)   # a constant of the car


def peak_slips(p: ModelParams, mu: float) -> tuple[float, float]:
    """(α_peak,f, α_peak,r) of the axles (rad): u* C D/K with u* the MF peak argument."""
    c = p.tyre_shape_lateral
    u_star = _peak_argument(c, p.tyre_curvature_lateral)
    fz_f, fz_r = axle_loads(p)
    return (u_star * c * mu * fz_f / (2.0 * p.c_cf), u_star * c * mu * fz_r / (2.0 * p.c_cr))


def steer_window(vx: float, vy: float, r: float, p: ModelParams, mu: float,
                 peaks: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) road-wheel angles (rad, front and rear) that keep each axle's
    kinematic slip α = δ − (v_y ± l r)/v_x within its peak slip at μ̂: steering beyond the
    peak gives no more force (module docstring). ``peaks``: :func:`peak_slips` at μ̂ when
    the caller has them."""
    vxs = max(vx, p.min_speed_mps)
    kin_f, kin_r = axle_directions(vy, r, vxs, p)
    pk_f, pk_r = peak_slips(p, mu) if peaks is None else peaks
    return np.array((kin_f - pk_f, kin_r - pk_r)), np.array((kin_f + pk_f, kin_r + pk_r))


def lateral_use(zeta: np.ndarray, p: ModelParams, mu: float) -> float:
    """η_y = max over the axles of |F(α̂')|/D at μ̂ (no longitudinal force)."""
    fz_f, fz_r = axle_loads(p)
    return _lateral_use(float(zeta[RelaxIdx.ALPHA_F]), float(zeta[RelaxIdx.ALPHA_R]),
                        2.0 * p.c_cf, 2.0 * p.c_cr, mu * fz_f, mu * fz_r,
                        p.tyre_shape_lateral, p.tyre_curvature_lateral)


@njit(cache=True)
def _lateral_use(alpha_f_rad: float, alpha_r_rad: float, k_f_n_per_rad: float,
                 k_r_n_per_rad: float, d_f_n: float, d_r_n: float, c: float, e: float
                 ) -> float:
    """:func:`lateral_use` of the axles' slips α̂', stiffnesses K and peaks D, compiled."""
    use = 0.0
    for alpha, k, d in ((alpha_f_rad, k_f_n_per_rad, d_f_n), (alpha_r_rad, k_r_n_per_rad,
                                                              d_r_n)):
        use = max(use, abs(force(alpha, k, d, c, e)[0]) / d)
    return min(use, 1.0)


def yaw_moment_bound(zeta: np.ndarray, p: ModelParams, mu: float, ax: float) -> float:
    """|M_z| the wheels' spare longitudinal grip can give (N·m, module docstring)."""
    spare = math.sqrt(1.0 - lateral_use(zeta, p, mu) ** 2) - abs(ax) / (mu * p.gravity_mps2)
    return max(0.0, 0.5 * p.track_width_m * mu * p.mass_kg * p.gravity_mps2 * spare)
