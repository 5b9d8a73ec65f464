"""The MPC controller of section 3: config, one step (errors, weights, horizons, QP), fallback.

One call of :meth:`MpcController.step` at time k:

1. nearest point on the reference and the errors e_Y (m, left +), e_φ (rad) (``reference``);
2. weights: fixed (Q_φ, Q_Y, R_Δδ, R_ΔMz from the config) or fuzzy (section 3.2,
   ``fuzzy_weights``) from (e_Y, e_φ);
3. horizons: fixed (N_p, N_c baseline) or APCHA (eq. 7-15, ``apcha``) from e_s, the previous
   e_s, the last applied increment and the previous horizons;
4. state ζ0 = [vy, vx, φ, r, Y, X] in the path frame at the nearest point
   (``prediction_frame = "path"``; "global" uses the map frame as printed in the paper),
   model of eq. (4) linearised at (ζ0, u(k−1)) (``model``);
5. reference outputs (φ_ref, Y_ref) at s + vx T i, i = 1..N_p;
6. the QP of eq. (16)-(20) (``qp``), warm-started from the previous plan shifted by one;
   hard bounds |vy| ≤ vx tan β_max and |r| ≤ factor μ g / vx on predicted steps
   i ≥ ``state_bounds_from_step``, each relaxed to the current |vy| or |r| when the car is
   already beyond it ("no worse than now": a bound the state already violates cannot be met
   within a few steps and would only make the QP infeasible);
7. u(k) = u(k−1) + Δu*(k), eq. (22).

Cost scaling (one for every controller, see docs/mpc.md): the paper's weights multiply
*normalised* channels, each divided by a characteristic size::

    J = Σ_i Q_φ (e_φ,i / s_φ)² + Q_Y (e_Y,i / s_Y)²
      + Σ_j R_Δδ [(Δδf,j / s_Δδ)² + (Δδr,j / s_Δδ)²] + R_ΔMz (ΔMz,j / s_ΔMz)² + ρ ε²

so the effective QP weights are q = (Q_φ/s_φ², Q_Y/s_Y²), r = (R_Δδ/s_Δδ², R_Δδ/s_Δδ²,
R_ΔMz/s_ΔMz²) with s_φ, s_Δδ in rad.

Fallback: when OSQP does not return a trusted status (or is infeasible because of the hard
bounds), the previous optimal plan is applied shifted by one step (u(k|k−1), then
u(k+1|k−2), ...); when it is used up, or there was none, the last command is held. The
result is flagged ``fallback`` and is always finite; QP data that OSQP would refuse (non-finite
or inconsistent) are a failed solve, never an update. A non-finite state, or one outside
the plausible ranges of :data:`fourws_common.input_guard.STATE_LIMITS`, raises
``ValueError`` before it changes anything.
The core never reads a clock.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np

from fourws_common.input_guard import STATE_LIMITS
from fourws_common.params import from_mapping, param
from fourws_mpc.core.apcha import ApchaParams, apcha, integrated_error
from fourws_mpc.core.fuzzy_weights import FuzzySpec, FuzzyWeights
from fourws_mpc.core.model import N_INPUT, N_STATE, InputIdx, ModelParams, StateIdx, discretise
from fourws_mpc.core.qp import MpcQp, QpBounds, QpSettings
from fourws_mpc.core.reference import Reference

G = 9.81


class MeasIdx(IntEnum):
    """Indices of a measured-state array given to :meth:`MpcController.step`."""

    X = 0
    Y = 1
    YAW = 2
    VX = 3
    VY = 4
    YAW_RATE = 5


@dataclass(frozen=True, slots=True)
class VehicleSample:
    """The measured state the MPC needs (SI, map frame / ISO body frame)."""

    x: float
    y: float
    yaw: float
    vx: float
    vy: float
    yaw_rate: float


@dataclass(frozen=True)
class MpcConfig:
    """Every parameter of the MPC (flat keys of ``fourws_mpc/config/mpc.yaml``)."""

    controller: str = param("improved", "controller preset name (reported in diagnostics)")
    use_rear_steer: bool = param(True, "rear steer is an input (else δr ≡ 0)")
    use_dyc: bool = param(True, "direct yaw moment is an input (else Mz ≡ 0)")
    weights_mode: str = param("fuzzy", "fixed weights or fuzzy adaptive weights (sec. 3.2)",
                              choices=("fixed", "fuzzy"))
    horizons_mode: str = param("apcha", "fixed horizons or APCHA (eq. 7-15)",
                               choices=("fixed", "apcha"))
    prediction_frame: str = param("path", "frame of the prediction: path-aligned at the "
                                  "nearest point, or the map frame", choices=("path", "global"))
    # fixed weights (section 4)
    q_phi: float = param(1.0, "fixed output weight Q_φ", lo=0.0, hi=1e9)
    q_y: float = param(10.0, "fixed output weight Q_Y", lo=0.0, hi=1e9)
    r_ddelta: float = param(1.0, "fixed steer-increment weight R_Δδ", lo=1e-9, hi=1e9)
    r_dmz: float = param(1.0, "fixed yaw-moment-increment weight R_ΔMz", lo=1e-9, hi=1e9)
    # fuzzy maxima, eq. (23)
    q_y_max: float = param(8000.0, "fuzzy maximum Q_Y,max", lo=0.0, hi=1e9)
    q_phi_max: float = param(5000.0, "fuzzy maximum Q_φ,max", lo=0.0, hi=1e9)
    r_ddelta_max: float = param(80000.0, "fuzzy maximum R_Δδ,max", lo=1e-9, hi=1e9)
    r_dmz_max: float = param(60000.0, "fuzzy maximum R_ΔMz,max", lo=1e-9, hi=1e9)
    fuzzy_e_y_range_m: float = param(3.0, "fuzzy universe of e_Y is ±this", lo=0.01, hi=100.0,
                                     unit="m")
    fuzzy_e_phi_range_deg: float = param(8.0, "fuzzy universe of e_φ is ±this", lo=0.01,
                                         hi=180.0, unit="deg")
    fuzzy_grid_y: int = param(121, "precomputed response-surface grid points along e_Y",
                              lo=5, hi=2001)
    fuzzy_grid_phi: int = param(161, "precomputed response-surface grid points along e_φ",
                                lo=5, hi=2001)
    fuzzy_out_points: int = param(201, "samples of the output universe [0, 1]", lo=11,
                                  hi=10001)
    # cost scaling (one for all controllers)
    scale_y_m: float = param(0.0059, "characteristic lateral error s_Y", lo=1e-6, hi=100.0,
                             unit="m")
    scale_phi_deg: float = param(0.30, "characteristic heading error s_φ", lo=1e-6, hi=180.0,
                                 unit="deg")
    scale_dsteer_front_deg: float = param(0.8, "characteristic front-steer increment s_Δδf",
                                          lo=1e-6, hi=90.0, unit="deg")
    scale_dsteer_rear_deg: float = param(1.04, "characteristic rear-steer increment s_Δδr",
                                         lo=1e-6, hi=90.0, unit="deg")
    scale_dmz_nm: float = param(300.0, "characteristic yaw-moment increment s_ΔMz", lo=1e-6,
                                hi=1e6, unit="N*m")
    rho: float = param(1000.0, "slack weight ρ of the soft output bounds", lo=0.0, hi=1e12)
    # horizons
    np_baseline: int = param(12, "prediction horizon N_p (fixed mode; APCHA start)", lo=1,
                             hi=200)
    nc_baseline: int = param(6, "control horizon N_c (fixed mode; APCHA start)", lo=1, hi=200)
    np_min: int = param(10, "APCHA N_p,min", lo=1, hi=200)
    np_max: int = param(30, "APCHA N_p,max", lo=1, hi=200)
    np_step: int = param(2, "APCHA ΔN_p", lo=0, hi=100)
    nc_min: int = param(3, "APCHA N_c,min", lo=1, hi=200)
    nc_max: int = param(10, "APCHA N_c,max", lo=1, hi=200)
    nc_step: int = param(1, "APCHA ΔN_c", lo=0, hi=100)
    apcha_eps1: float = param(0.2, "APCHA ε1 (threshold on e_s)", lo=0.0, hi=100.0)
    apcha_eps2: float = param(0.5, "APCHA ε2 (threshold on k_e)", lo=0.0, hi=1e6, unit="1/s")
    apcha_eps3: float = param(0.3, "APCHA ε3 (threshold on k_u)", lo=0.0, hi=100.0)
    apcha_lambda: float = param(0.5, "APCHA λ, weight of the heading error in e_s",
                                lo=1e-6, hi=0.999999)
    apcha_e_y_max_m: float = param(0.5, "e_Y,max of eq. (7)", lo=1e-6, hi=100.0, unit="m")
    apcha_e_phi_max_deg: float = param(8.0, "e_φ,max of eq. (7)", lo=1e-6, hi=180.0,
                                       unit="deg")
    apcha_np_rate_limit: bool = param(True, "N_p moves by at most ΔN_p per period")
    apcha_nc_base: str = param("previous", "N_c^i of eq. (14): the previous N_c or ⌊N_p^t/3⌋",
                               choices=("previous", "np_third"))
    # constraints, eq. (20) and section 3.1.5
    max_steer_front_deg: float = param(30.0, "|δf| bound", lo=0.0, hi=90.0, unit="deg")
    max_steer_rear_deg: float = param(10.0, "|δr| bound", lo=0.0, hi=90.0, unit="deg")
    max_dsteer_front_deg: float = param(0.8, "|Δδf| per step", lo=1e-6, hi=90.0, unit="deg")
    max_dsteer_rear_deg: float = param(0.6, "|Δδr| per step", lo=1e-6, hi=90.0, unit="deg")
    max_yaw_moment_nm: float = param(1500.0, "|Mz| bound", lo=0.0, hi=1e6, unit="N*m")
    max_dyaw_moment_nm: float = param(300.0, "|ΔMz| per step", lo=1e-6, hi=1e6, unit="N*m")
    state_bounds: bool = param(True, "impose the hard sideslip and yaw-rate bounds")
    state_bounds_from_step: int = param(3, "first prediction step i with the hard bounds "
                                        "(earlier steps are fixed by the current state)",
                                        lo=1, hi=200)
    max_sideslip_deg: float = param(6.0, "hard |β| bound, as |vy| ≤ vx tan β_max", lo=0.01,
                                    hi=90.0, unit="deg")
    yaw_rate_mu_factor: float = param(0.85, "hard |r| ≤ factor μ g / vx", lo=0.01, hi=10.0)
    mu_default: float = param(1.0, "adhesion used for the yaw-rate bound when the state "
                              "carries none", lo=0.01, hi=3.0)
    soft_band_y_m: float = param(0.5, "soft bound |Y − Y_ref| ≤ band (1 + ε)", lo=1e-6,
                                 hi=100.0, unit="m")
    soft_band_phi_deg: float = param(8.0, "soft bound |φ − φ_ref| ≤ band (1 + ε)", lo=1e-6,
                                     hi=180.0, unit="deg")
    # prediction model, eq. (1)
    mass_kg: float = param(750.0, "vehicle mass m", lo=1.0, hi=1e5, unit="kg")
    yaw_inertia_kgm2: float = param(750.0, "yaw inertia I_z", lo=1.0, hi=1e6, unit="kg*m^2")
    cg_to_front_m: float = param(1.10, "CG to front axle a", lo=0.01, hi=10.0, unit="m")
    cg_to_rear_m: float = param(1.25, "CG to rear axle b", lo=0.01, hi=10.0, unit="m")
    cornering_stiffness_front_npr: float = param(27994.0, "per-tyre front cornering "
                                                 "stiffness C_cf", lo=1.0, hi=1e7, unit="N/rad")
    cornering_stiffness_rear_npr: float = param(29999.0, "per-tyre rear cornering "
                                                "stiffness C_cr", lo=1.0, hi=1e7, unit="N/rad")
    longitudinal_stiffness_front_n: float = param(50000.0, "per-tyre C_lf", lo=0.0, hi=1e7,
                                                  unit="N")
    longitudinal_stiffness_rear_n: float = param(50000.0, "per-tyre C_lr", lo=0.0, hi=1e7,
                                                 unit="N")
    slip_ratio_front: float = param(0.0, "S_f of eq. (1)", lo=-1.0, hi=1.0)
    slip_ratio_rear: float = param(0.0, "S_r of eq. (1)", lo=-1.0, hi=1.0)
    min_speed_mps: float = param(1.0, "vx floor in the slip angles", lo=0.01, hi=50.0,
                                 unit="m/s")
    dt_s: float = param(0.01, "control period and prediction step T", lo=1e-4, hi=1.0,
                        unit="s")
    # solver
    osqp_eps_abs: float = param(1e-4, "OSQP absolute tolerance", lo=1e-10, hi=1.0)
    osqp_eps_rel: float = param(1e-4, "OSQP relative tolerance", lo=1e-10, hi=1.0)
    osqp_max_iter: int = param(4000, "OSQP iteration limit", lo=10, hi=1000000)
    osqp_polishing: bool = param(False, "OSQP solution polishing")
    osqp_check_termination: int = param(5, "OSQP checks convergence every this many "
                                        "iterations", lo=1, hi=1000)
    osqp_accept_inaccurate: bool = param(False, "trust OSQP status 'solved inaccurate'")
    osqp_prebuild: bool = param(True, "set up the OSQP instance of every reachable (N_p, N_c) "
                                "at start-up (no set-up cost inside the control loop)")
    ref_search_back: int = param(50, "nearest-point window behind the last index", lo=1,
                                 hi=1000000, unit="samples")
    ref_search_ahead: int = param(400, "nearest-point window ahead of the last index", lo=2,
                                  hi=1000000, unit="samples")

    def __post_init__(self) -> None:
        if self.np_min > self.np_max:
            raise ValueError(f"np_min, np_max: need np_min <= np_max, got {self.np_min}, "
                             f"{self.np_max}")
        if self.nc_min > self.nc_max:
            raise ValueError(f"nc_min, nc_max: need nc_min <= nc_max, got {self.nc_min}, "
                             f"{self.nc_max}")
        if self.nc_baseline > self.np_baseline:
            raise ValueError("nc_baseline, np_baseline: need N_c <= N_p, got "
                             f"{self.nc_baseline} > {self.np_baseline}")
        if self.horizons_mode == "apcha":
            if not self.np_min <= self.np_baseline <= self.np_max:
                raise ValueError("np_baseline: must lie in [np_min, np_max] with APCHA")
            if not self.nc_min <= self.nc_baseline <= self.nc_max:
                raise ValueError("nc_baseline: must lie in [nc_min, nc_max] with APCHA")
            if self.np_min // 3 < 1:
                raise ValueError("np_min: ⌊np_min/3⌋ must be >= 1 for the N_c clamp of eq. (15)")

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], *, strict: bool = True) -> MpcConfig:
        """Build and validate from a flat mapping (e.g. a merged ROS params file)."""
        return from_mapping(cls, values, strict=strict)

    def model_params(self) -> ModelParams:
        """Parameters of eq. (1) in SI."""
        return ModelParams(
            mass_kg=self.mass_kg, yaw_inertia_kgm2=self.yaw_inertia_kgm2,
            a_m=self.cg_to_front_m, b_m=self.cg_to_rear_m,
            c_cf=self.cornering_stiffness_front_npr, c_cr=self.cornering_stiffness_rear_npr,
            c_lf=self.longitudinal_stiffness_front_n, c_lr=self.longitudinal_stiffness_rear_n,
            slip_front=self.slip_ratio_front, slip_rear=self.slip_ratio_rear,
            min_speed_mps=self.min_speed_mps)

    @property
    def du_max(self) -> np.ndarray:
        """|Δu| bounds per step (rad, rad, N·m)."""
        return np.array([math.radians(self.max_dsteer_front_deg),
                         math.radians(self.max_dsteer_rear_deg), self.max_dyaw_moment_nm])

    @property
    def u_max(self) -> np.ndarray:
        """|u| bounds (rad, rad, N·m)."""
        return np.array([math.radians(self.max_steer_front_deg),
                         math.radians(self.max_steer_rear_deg), self.max_yaw_moment_nm])

    @property
    def enabled(self) -> np.ndarray:
        """Which inputs are free: δf always, δr with rear steer, Mz with DYC."""
        return np.array([True, self.use_rear_steer, self.use_dyc])

    def apcha_params(self) -> ApchaParams:
        """APCHA constants in SI."""
        return ApchaParams(
            np_min=self.np_min, np_max=self.np_max, np_step=self.np_step,
            nc_min=self.nc_min, nc_max=self.nc_max, nc_step=self.nc_step,
            eps1=self.apcha_eps1, eps2=self.apcha_eps2, eps3=self.apcha_eps3,
            lam=self.apcha_lambda, e_y_max=self.apcha_e_y_max_m,
            e_phi_max=math.radians(self.apcha_e_phi_max_deg),
            du_max=tuple(float(v) for v in self.du_max), dt_s=self.dt_s,
            np_rate_limit=self.apcha_np_rate_limit, nc_base=self.apcha_nc_base)

    def horizon_pairs(self) -> list[tuple[int, int]]:
        """Every (N_p, N_c) this configuration can use (baseline; all pairs of eq. (15))."""
        pairs = {(self.np_baseline, self.nc_baseline)}
        if self.horizons_mode == "apcha":
            for n_p in range(self.np_min, self.np_max + 1):
                lo = max(n_p // 3, min(self.nc_min, n_p // 2))
                hi = max(n_p // 3, min(self.nc_max, n_p // 2))
                pairs.update((n_p, n_c) for n_c in range(lo, hi + 1))
        return sorted(pairs)

    def fuzzy_spec(self) -> FuzzySpec:
        """Universes and grid of the fuzzy scheduler."""
        return FuzzySpec(self.fuzzy_e_y_range_m, self.fuzzy_e_phi_range_deg,
                         self.fuzzy_grid_y, self.fuzzy_grid_phi, self.fuzzy_out_points)

    def effective_weights(self, q_phi: float, q_y: float, r_dd: float, r_dmz: float
                          ) -> tuple[np.ndarray, np.ndarray]:
        """(q_eff (2,), r_eff (3,)) of the QP from paper-scale weights (cost scaling)."""
        s_phi = math.radians(self.scale_phi_deg)
        s_df = math.radians(self.scale_dsteer_front_deg)
        s_dr = math.radians(self.scale_dsteer_rear_deg)
        q = np.array([q_phi / s_phi**2, q_y / self.scale_y_m**2])
        r = np.array([r_dd / s_df**2, r_dd / s_dr**2, r_dmz / self.scale_dmz_nm**2])
        return q, r


def equal_effect_scaling(cfg: MpcConfig, speed_mps: float = 60.0 / 3.6
                         ) -> dict[str, float]:
    """The cost scaling's characteristic sizes derived from the prediction model.

    At straight driving at ``speed_mps`` over the baseline horizon N_p (eq. 6): s_Y and s_φ
    are the changes of Y and φ at step N_p after one maximal front-steer increment Δδf,max
    (held), s_Δδr the rear-steer increment with the same lateral effect. Returns
    ``scale_y_m``, ``scale_phi_deg``, ``scale_dsteer_rear_deg`` (docs/mpc.md).
    """
    from fourws_mpc.core.model import discretise as _disc
    from fourws_mpc.core.qp import augment, output_matrix, prediction_matrices

    zeta = np.zeros(N_STATE)
    zeta[StateIdx.VX] = speed_mps
    Ak, Bk, dk = _disc(zeta, np.zeros(N_INPUT), cfg.model_params(), cfg.dt_s)
    Aa, Ba, _ = augment(Ak, Bk, dk)
    n_p = cfg.np_baseline
    _, theta, _ = prediction_matrices(Aa, Ba, output_matrix(), n_p, 1)
    last = theta.reshape(n_p, -1, N_INPUT)[-1]         # rows φ, Y, vy, r at step N_p
    dmax = cfg.du_max
    y_f = abs(last[1, InputIdx.DF]) * dmax[InputIdx.DF]
    phi_f = abs(last[0, InputIdx.DF]) * dmax[InputIdx.DF]
    dr = y_f / abs(last[1, InputIdx.DR])
    return {"scale_y_m": float(y_f), "scale_phi_deg": math.degrees(phi_f),
            "scale_dsteer_rear_deg": math.degrees(dr)}


@dataclass(frozen=True, slots=True)
class MpcResult:
    """Command (SI) and diagnostics of one MPC step."""

    delta_front: float
    delta_rear: float
    yaw_moment: float
    controller: str
    np: int
    nc: int
    q_y: float
    q_phi: float
    r_ddelta: float
    r_dmz: float
    lateral_error: float
    heading_error: float
    e_s: float
    k_e: float
    k_u: float
    solver_status: str
    iterations: int
    slack: float
    fallback: bool
    ref_index: int = 0
    ref_speed: float = 0.0


def _read_state(state: Any) -> tuple[float, float, float, float, float, float]:
    if hasattr(state, "yaw_rate"):
        vals = (state.x, state.y, state.yaw, state.vx, state.vy, state.yaw_rate)
    else:
        a = np.asarray(state, dtype=float).reshape(-1)
        if a.size < len(MeasIdx):
            raise ValueError(f"state: need {len(MeasIdx)} values (MeasIdx), got {a.size}")
        vals = tuple(a[i] for i in MeasIdx)
    out = tuple(float(v) for v in vals)
    for name, v in zip(("x", "y", "yaw", "vx", "vy", "yaw_rate"), out, strict=True):
        if not math.isfinite(v):
            raise ValueError(f"state {name}: not finite ({v!r})")
        lo, hi = STATE_LIMITS[name]
        if not lo <= v <= hi:
            # finite but absurd (x = 1e300): it would overflow the projection and the QP
            raise ValueError(f"state {name}: {v!r} outside the plausible range {lo:g}..{hi:g}")
    return out  # type: ignore[return-value]


class MpcController:
    """Section 3's MPC; one instance per vehicle. Stateful: previous input, plan, horizons."""

    def __init__(self, cfg: MpcConfig | None = None) -> None:
        self.cfg = cfg if cfg is not None else MpcConfig()
        self.fuzzy: FuzzyWeights | None = None
        self._apply(self.cfg, None)
        self._stepped = False
        self.reset()

    @staticmethod
    def _qp_settings(c: MpcConfig) -> QpSettings:
        return QpSettings(eps_abs=c.osqp_eps_abs, eps_rel=c.osqp_eps_rel,
                          max_iter=c.osqp_max_iter, polishing=c.osqp_polishing,
                          accept_inaccurate=c.osqp_accept_inaccurate,
                          check_termination=c.osqp_check_termination)

    def _apply(self, c: MpcConfig, old: MpcConfig | None) -> None:
        """Derive everything that depends on the config; rebuild only what changed."""
        self.model = c.model_params()
        self.apcha_params = c.apcha_params()
        if c.weights_mode != "fuzzy":
            self.fuzzy = None
        elif self.fuzzy is None or old is None or c.fuzzy_spec() != old.fuzzy_spec():
            self.fuzzy = FuzzyWeights(c.fuzzy_spec())
        settings = self._qp_settings(c)
        if old is None or settings != self.qp.settings:
            self.qp = MpcQp(settings)
        self._du_max = c.du_max
        self._u_max = c.u_max
        self._enabled = c.enabled
        if c.osqp_prebuild:
            for n_p, n_c in c.horizon_pairs():
                self.qp.instance(n_p, n_c)

    def update_config(self, cfg: MpcConfig) -> None:
        """Apply a new configuration to the running controller without losing its state.

        u(k−1), the last increment, the stored plan, the horizons (clamped into the new
        APCHA range, or the new baseline in fixed mode), e_s(k−1) and the reference index are
        kept; the fuzzy surface and the OSQP instances are rebuilt only if their own settings
        changed. An equal config is a no-op.
        """
        old = self.cfg
        if cfg == old:
            return
        self.cfg = cfg
        self._apply(cfg, old)
        self.u_prev = np.where(self._enabled,
                               np.minimum(np.maximum(self.u_prev, -self._u_max), self._u_max),
                               0.0)
        if cfg.horizons_mode == "apcha":
            self.n_p = min(max(self.n_p, cfg.np_min), cfg.np_max)
            self.n_c = min(max(self.n_c, cfg.nc_min), cfg.nc_max, self.n_p)
        else:
            self.n_p, self.n_c = cfg.np_baseline, cfg.nc_baseline

    def adopt_reference(self, ref: Reference) -> None:
        """Use ``ref`` (the same path, e.g. with another search window) from the next step on
        and keep the nearest-point index, instead of a global search as for a new path."""
        if self._ref is not None:
            self._ref = ref

    def reset(self, u_prev: np.ndarray | None = None) -> None:
        """Forget the past: u(k−1) (default zeros), plan, horizons, reference index, and the
        solvers' internal state (OSQP keeps its adapted ρ and duals between solves), so a
        reset controller answers exactly as a new one."""
        if self._stepped:
            self.qp = MpcQp(self.qp.settings)
            if self.cfg.osqp_prebuild:
                for n_p, n_c in self.cfg.horizon_pairs():
                    self.qp.instance(n_p, n_c)
            self._stepped = False
        u = np.zeros(N_INPUT) if u_prev is None else np.asarray(u_prev, float).copy()
        self.u_prev = np.where(self._enabled, np.clip(u, -self._u_max, self._u_max), 0.0)
        self.du_last = np.zeros(N_INPUT)
        self.plan_u: np.ndarray | None = None
        self.plan_du_scaled: np.ndarray | None = None
        self.plan_pos = 0
        self.n_p = self.cfg.np_baseline
        self.n_c = self.cfg.nc_baseline
        self.e_s_prev: float | None = None
        self.ref_hint: int | None = None
        self._ref: Reference | None = None

    def _weights(self, e_y: float, e_phi: float) -> tuple[float, float, float, float]:
        c = self.cfg
        if self.fuzzy is None:
            return c.q_y, c.q_phi, c.r_ddelta, c.r_dmz
        r = self.fuzzy.ratios(e_y, e_phi)
        return (float(r[0] * c.q_y_max), float(r[1] * c.q_phi_max),
                float(r[2] * c.r_ddelta_max), float(r[3] * c.r_dmz_max))

    def step(self, t_s: float, state: Any, ref: Reference, mu: float | None = None
             ) -> MpcResult:
        """One control period.

        t_s: time of the state (s, for the record only); state: object with x, y, yaw, vx, vy,
        yaw_rate or an array indexed by :class:`MeasIdx` (SI); ref: the reference path;
        mu: road adhesion for the yaw-rate bound (default ``mu_default``).
        """
        c = self.cfg
        x, y, yaw, vx, vy, r = _read_state(state)
        self._stepped = True
        if mu is not None and not math.isfinite(mu):
            raise ValueError(f"mu: not finite ({mu!r})")
        hint = self.ref_hint if ref is self._ref else None
        err = ref.errors(x, y, yaw, hint)
        near = err.near
        e_y, e_phi = err.lateral_error, err.heading_error

        q_y, q_phi, r_dd, r_dmz = self._weights(e_y, e_phi)
        e_s = integrated_error(e_y, e_phi, self.apcha_params)
        if c.horizons_mode == "apcha":
            h = apcha(e_s, self.e_s_prev, self.du_last, self.n_p, self.n_c, self.apcha_params)
            n_p, n_c, k_e, k_u = h.n_p, h.n_c, h.k_e, h.k_u
        else:
            n_p, n_c = c.np_baseline, c.nc_baseline
            k_e = 0.0 if self.e_s_prev is None else abs(e_s - self.e_s_prev) / c.dt_s
            k_u = float(np.max(np.abs(self.du_last) / self._du_max))

        zeta = np.zeros(N_STATE)
        zeta[StateIdx.VY], zeta[StateIdx.VX], zeta[StateIdx.R] = vy, vx, r
        if c.prediction_frame == "path":
            X, Y, phi = ref.to_path_frame(near, x, y, yaw)
        else:
            X, Y = x, y
            phi = yaw
        zeta[StateIdx.PHI], zeta[StateIdx.Y], zeta[StateIdx.X] = phi, Y, X
        phi_ref, y_ref = ref.horizon(near, vx, c.dt_s, n_p, yaw, c.prediction_frame)
        ref_out = np.column_stack([phi_ref, y_ref])

        Ak, Bk, dk = discretise(zeta, self.u_prev, self.model, c.dt_s)
        vxb = max(vx, c.min_speed_mps)
        mu_b = c.mu_default if mu is None else max(float(mu), 0.01)
        bounds = QpBounds(
            du_max=self._du_max, u_max=self._u_max, enabled=self._enabled,
            vy_max=max(vxb * math.tan(math.radians(c.max_sideslip_deg)), abs(vy)),
            r_max=max(c.yaw_rate_mu_factor * mu_b * G / vxb, abs(r)),
            band_phi=math.radians(c.soft_band_phi_deg), band_y=c.soft_band_y_m,
            state_bounds=c.state_bounds, state_bounds_from_step=c.state_bounds_from_step)
        q_eff, r_eff = c.effective_weights(q_phi, q_y, r_dd, r_dmz)
        sol = self.qp.solve(Ak, Bk, dk, zeta, self.u_prev, ref_out, n_p, n_c, q_eff, r_eff,
                            c.rho, bounds, warm_du_scaled=self._warm(n_c))

        if sol.ok:
            u = sol.u[0].copy()
            self.plan_u = sol.u.copy()
            self.plan_du_scaled = sol.du_scaled.copy()
            self.plan_pos = 0
            fallback = False
        else:
            fallback = True
            u = self._fallback_input()
        u = np.where(self._enabled, np.minimum(np.maximum(u, -self._u_max), self._u_max), 0.0)
        # the step's history is committed only here: a step that raised changed nothing
        self.du_last = u - self.u_prev
        self.u_prev = u
        self.n_p, self.n_c = n_p, n_c
        self.e_s_prev = e_s
        self._ref, self.ref_hint = ref, near.index
        return MpcResult(
            delta_front=float(u[InputIdx.DF]), delta_rear=float(u[InputIdx.DR]),
            yaw_moment=float(u[InputIdx.MZ]), controller=c.controller, np=int(n_p),
            nc=int(n_c), q_y=q_y, q_phi=q_phi, r_ddelta=r_dd, r_dmz=r_dmz,
            lateral_error=float(e_y), heading_error=float(e_phi), e_s=float(e_s),
            k_e=float(k_e), k_u=float(k_u), solver_status=sol.status,
            iterations=sol.iterations, slack=float(sol.slack), fallback=fallback,
            ref_index=near.index, ref_speed=near.speed)

    def _warm(self, n_c: int) -> np.ndarray | None:
        """Previous plan's scaled increments shifted by one step, resized to N_c."""
        if self.plan_du_scaled is None:
            return None
        shifted = self.plan_du_scaled[self.plan_pos + 1:]
        out = np.zeros((n_c, N_INPUT))
        k = min(n_c, len(shifted))
        out[:k] = shifted[:k]
        return out

    def _fallback_input(self) -> np.ndarray:
        """Next input of the stored plan (shifted by one step), else hold the last command."""
        if self.plan_u is not None and self.plan_pos + 1 < len(self.plan_u):
            self.plan_pos += 1
            return self.plan_u[self.plan_pos].copy()
        self.plan_u = None
        self.plan_du_scaled = None
        return self.u_prev.copy()
