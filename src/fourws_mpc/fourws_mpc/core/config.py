"""Holds every parameter of the MPC of section 3 as one frozen dataclass (``mpc.yaml``'s keys).

The values live in ``fourws_mpc/config/mpc.yaml`` (a unit test checks the file and the
defaults here agree); the controller presets of ``fourws_bringup/config/controllers/`` override
what differs (docs/graph.md, "Configuration"). Degrees only where the key says ``_deg``; SI
otherwise. The vehicle constants use the plant's names (the car file,
``fourws_common/config/vehicles/NAME.yaml``); a unit test keeps their nominal values equal to
the plant's, so a model mismatch is always an explicit override.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from fourws_common.params import from_mapping, param
from fourws_common.vehicle_info import field_range
from fourws_mpc.core.apcha import ApchaParams, clamp_nc
from fourws_mpc.core.fuzzy_weights import FuzzySpec
from fourws_mpc.core.model import ModelParams
from fourws_mpc.core.prediction_model import (
    DISCRETISATIONS,
    PREDICTION_MODELS,
    RELAXATION_MODELS,
)
from fourws_mpc.core.qp_solver import QP_SOLVERS
from fourws_mpc.core.reference import SEARCH_AHEAD, SEARCH_BACK, Reference


@dataclass(frozen=True)
class MpcConfig:
    """Every parameter of the MPC (flat keys of ``fourws_mpc/config/mpc.yaml``)."""

    controller: str = param("improved", "controller preset name (reported in diagnostics)")
    law: str = param("mpc", "control law: the MPC of section 3, or the textbook reference "
                     "(front-steer LQR with curvature feed-forward, core.lqr)",
                     choices=("mpc", "lqr_ff"))
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
    # beyond the paper (docs/mpc.md, "The yaw moment's level")
    mz_level_weight: float = param(
        0.0088, "weight of the yaw moment's level |Mz(k+i)|, i = 0..Np−1, relative to its "
        "increment weight R_ΔMz (both on Mz / scale_dmz_nm); 0 is the paper's cost", lo=0.0,
        hi=1e3)
    # beyond the paper (docs/mpc.md, "A terminal cost")
    terminal_cost: str = param(
        "none", "cost after the horizon: none (the paper's eq. 16) or lqr (the velocity-form "
        "LQR cost-to-go of the same stage weights; with front steer alone of Y's level only, "
        "terminal_cost.py)", choices=("none", "lqr"))
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
    max_steer_front_deg: float = param(30.0, "|δf| bound", **field_range("max_steer_front_deg"))
    max_steer_rear_deg: float = param(10.0, "|δr| bound", **field_range("max_steer_rear_deg"))
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
    mu_from_state: bool = param(True, "take μ from the state when it carries one (the "
                                "plant's truth in the idealised world); false: a car, which "
                                "measures none (estimated, or mu_default)")
    soft_band_y_m: float = param(0.5, "soft bound |Y − Y_ref| ≤ band (1 + ε)", lo=1e-6,
                                 hi=100.0, unit="m")
    soft_band_phi_deg: float = param(8.0, "soft bound |φ − φ_ref| ≤ band (1 + ε)", lo=1e-6,
                                     hi=180.0, unit="deg")
    # prediction model, eq. (1)
    prediction_model: str = param("single_track_relaxation", "prediction model behind the "
                                  "model seam (prediction_model.PREDICTION_MODELS)",
                                  choices=tuple(PREDICTION_MODELS))
    mass_kg: float = param(750.0, "vehicle mass m", **field_range("mass_kg"))
    yaw_inertia_kg_m2: float = param(750.0, "yaw inertia I_z", **field_range("yaw_inertia_kg_m2"))
    cg_to_front_axle_m: float = param(1.10, "CG to front axle a",
                                      **field_range("cg_to_front_axle_m"))
    cg_to_rear_axle_m: float = param(1.25, "CG to rear axle b", **field_range("cg_to_rear_axle_m"))
    cornering_stiffness_front_static_n_per_rad: float = param(
        27994.0, "per-tyre front cornering stiffness C_cf",
        **field_range("cornering_stiffness_front_static_n_per_rad"))
    cornering_stiffness_rear_static_n_per_rad: float = param(
        29999.0, "per-tyre rear cornering stiffness C_cr",
        **field_range("cornering_stiffness_rear_static_n_per_rad"))
    longitudinal_stiffness_front_n: float = param(50000.0, "per-tyre C_lf", lo=0.0, hi=1e7,
                                                  unit="N")
    longitudinal_stiffness_rear_n: float = param(50000.0, "per-tyre C_lr", lo=0.0, hi=1e7,
                                                 unit="N")
    slip_ratio_front: float = param(0.0, "S_f of eq. (1)", lo=-1.0, hi=1.0)
    slip_ratio_rear: float = param(0.0, "S_r of eq. (1)", lo=-1.0, hi=1.0)
    min_speed_mps: float = param(1.0, "vx floor in the slip angles", lo=0.01, hi=50.0,
                                 unit="m/s")
    # friction-aware prediction and grip envelope (docs/mpc.md, "Friction-aware prediction")
    gravity_mps2: float = param(9.81, "gravity g", **field_range("gravity_mps2"))
    track_width_m: float = param(1.30, "track width B (front = rear)",
                                 **field_range("track_width_front_m"))
    tyre_shape_lateral: float = param(1.3, "Magic Formula shape factor C of the axle tyre",
                                      **field_range("tyre_shape_lateral"))
    tyre_curvature_lateral: float = param(-1.0, "Magic Formula curvature factor E of the "
                                          "axle tyre", **field_range("tyre_curvature_lateral"))
    cg_height_m: float = param(0.54, "CG height h (the tyres' loads in the prediction and "
                               "the μ estimate)", **field_range("cg_height_m"))
    roll_stiffness_front_share: float = param(
        0.55, "front share of the roll stiffness (the tyres' loads in the prediction and the "
        "μ estimate)",
        **field_range("roll_stiffness_front_share"))
    tyre_nominal_load_n: float = param(2000.0, "tyre nominal load F_z0 (a tyre's stiffness "
                                       "at its load)",
                                       **field_range("tyre_nominal_load_n"))
    tyre_cornering_load_factor: float = param(
        2.0, "p_Ky2: the tyre's K_alpha peaks at F_z = p_Ky2 F_z0 (a tyre's stiffness at its "
        "load)", **field_range("tyre_cornering_load_factor"))
    mu_floor: float = param(0.1, "μ estimate is clamped to at least this (and flagged)",
                            lo=0.01, hi=1.0)
    mu_ceiling: float = param(1.2, "μ estimate is clamped to at most this (and flagged)",
                              lo=0.1, hi=3.0)
    mu_evidence_deficit: float = param(
        0.1, "the car's lateral force m a_y below the linear tyres' K_f α_f + K_r α_r by this "
        "share of its weight m g is evidence of the peak (grip.py)", lo=0.01, hi=1.0)
    mu_evidence_max_ax: float = param(
        0.31, "evidence only under mostly lateral use, |a_x| <= this share of μ̂ g (the "
        "friction ellipse then takes at most 5 % of the lateral grip); else μ̂ holds "
        "(grip.py)", lo=0.0, hi=1.0)
    mu_evidence_min_ask: float = param(
        0.3, "evidence only while the linear tyres' force asks for at least this share of "
        "the grip the prior mu_default allows (a deficit at a smaller ask is the slip "
        "observer's error; grip.py)", lo=0.0, hi=1.0)
    mu_evidence_min_speed_mps: float = param(
        10.0, "evidence only at or above this speed, else μ̂ holds (the slip observer's "
        "error from a lateral-velocity error e is e/v_x; grip.py)", lo=0.0, hi=100.0,
        unit="m/s")
    envelope_softness: float = param(
        1e-3, "friction-aware: the β and r bounds are soft, the slack ε relaxing them by this "
        "share of the bound (ε priced by rho like the tracking band)", lo=1e-4, hi=10.0)
    mu_fall_time_s: float = param(0.05, "time constant of a falling μ estimate", lo=1e-3,
                                  hi=10.0, unit="s")
    mu_rise_time_s: float = param(1.0, "time constant of a rising μ estimate, and of its "
                                  "return to mu_default without evidence", lo=1e-3,
                                  hi=100.0, unit="s")
    dt_s: float = param(0.01, "control period and prediction step T", lo=1e-4, hi=1.0,
                        unit="s")
    # beyond assumption (6) (docs/mpc.md, "Actuator-aware prediction", "Delay compensation")
    prediction_discretisation: str = param(
        "zoh", "discretisation of the linearised model: forward Euler (eq. 4) or the exact "
        "zero-order hold", choices=DISCRETISATIONS)
    steer_front_time_constant_s: float = param(
        0.02, "front steering lag τ_f of the single_track_actuators model",
        **field_range("steer_front_time_constant_s"))
    steer_rear_time_constant_s: float = param(
        0.02, "rear steering lag τ_r of the single_track_actuators model",
        **field_range("steer_rear_time_constant_s"))
    relaxation_length_front_m: float = param(
        0.2199, "front tyres' lateral relaxation length σ_f at static load, of the "
        "single_track_relaxation model", lo=1e-3, hi=10.0, unit="m")
    relaxation_length_rear_m: float = param(
        0.1995, "rear tyres' lateral relaxation length σ_r at static load, of the "
        "single_track_relaxation model", lo=1e-3, hi=10.0, unit="m")
    input_delay_periods: int = param(0, "known computation delay compensated by prediction "
                                     "(a command computed at k acts from k + N)", lo=0,
                                     hi=100, unit="periods")
    steer_dead_time_s: float = param(0.0, "known steering dead time compensated by "
                                     "prediction (rounded to periods)", lo=0.0, hi=1.0,
                                     unit="s")
    # lqr_ff (law: lqr_ff): Bryson's rule, the largest acceptable value of each error state
    # and of the steer angle (core.lqr.LqrWeights)
    lqr_e1_max_m: float = param(0.05, "Bryson maximum of the lateral error", lo=1e-4,
                                hi=10.0, unit="m")
    lqr_e1_dot_max_mps: float = param(0.5, "Bryson maximum of its rate", lo=1e-4, hi=50.0,
                                      unit="m/s")
    lqr_e2_max_deg: float = param(1.0, "Bryson maximum of the heading error", lo=1e-3,
                                  hi=90.0, unit="deg")
    lqr_e2_dot_max_deg_s: float = param(10.0, "Bryson maximum of its rate", lo=1e-3,
                                        hi=1000.0, unit="deg/s")
    lqr_steer_max_deg: float = param(5.0, "Bryson maximum of the front steer angle",
                                     lo=1e-3, hi=90.0, unit="deg")
    # solver
    qp_solver: str = param("daqp", "QP solver behind the solver seam (qp_solver.QP_SOLVERS)",
                           choices=tuple(QP_SOLVERS))
    osqp_eps_abs: float = param(1e-4, "OSQP absolute tolerance", lo=1e-10, hi=1.0)
    osqp_eps_rel: float = param(1e-4, "OSQP relative tolerance", lo=1e-10, hi=1.0)
    qp_max_iter: int = param(4000, "iteration limit of the QP solver (OSQP: ADMM "
                             "iterations; DAQP: active-set changes)", lo=10, hi=1000000)
    osqp_polishing: bool = param(False, "OSQP solution polishing")
    osqp_check_termination: int = param(5, "OSQP checks convergence every this many "
                                        "iterations", lo=1, hi=1000)
    osqp_accept_inaccurate: bool = param(False, "trust OSQP status 'solved inaccurate'")
    qp_prebuild: bool = param(True, "set up the solver's instance of every reachable "
                              "(N_p, N_c) at start-up (no set-up cost inside the control "
                              "loop)")
    ref_search_back: int = param(SEARCH_BACK, "nearest-point window behind the last index", lo=1,
                                 hi=1000000, unit="samples")
    ref_search_ahead: int = param(SEARCH_AHEAD, "nearest-point window ahead of the last "
                                  "index", lo=2, hi=1000000, unit="samples")

    def __post_init__(self) -> None:
        if self.np_min > self.np_max:
            raise ValueError(f"np_min, np_max: need np_min <= np_max, got {self.np_min}, "
                             f"{self.np_max}")
        if self.nc_min > self.nc_max:
            raise ValueError(f"nc_min, nc_max: need nc_min <= nc_max, got {self.nc_min}, "
                             f"{self.nc_max}")
        np_least = (min(self.np_baseline, self.np_min) if self.horizons_mode == "apcha"
                    else self.np_baseline)
        if self.terminal_cost == "lqr" and np_least < 2:
            raise ValueError(f"terminal_cost: lqr needs N_p >= 2, got {np_least} (np_baseline, "
                             "np_min with APCHA)")
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
        if self.mu_floor > self.mu_ceiling:
            raise ValueError(f"mu_floor, mu_ceiling: need floor <= ceiling, got "
                             f"{self.mu_floor}, {self.mu_ceiling}")
        if self.prediction_model in RELAXATION_MODELS and \
                self.prediction_discretisation == "euler":
            sigma = min(self.relaxation_length_front_m, self.relaxation_length_rear_m)
            raise ValueError(
                "prediction_discretisation: the relaxation lag σ/vx is shorter than 2T above "
                f"vx = {sigma / (2 * self.dt_s):.0f} m/s, where forward Euler oscillates or "
                "diverges; use zoh with single_track_relaxation")
        if (self.prediction_model in ("single_track_actuators", *RELAXATION_MODELS)
                and self.prediction_discretisation == "euler"):
            tau = min(self.steer_front_time_constant_s, self.steer_rear_time_constant_s)
            if tau < 2.0 * self.dt_s:
                raise ValueError(
                    f"steer_front/rear_time_constant_s: forward Euler of a {tau} s lag at "
                    f"dt_s = {self.dt_s} s has the pole 1 − T/τ = {1 - self.dt_s / tau:.2f} "
                    "(unstable or oscillating below τ = 2T); use prediction_discretisation: zoh")

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], *, strict: bool = True) -> MpcConfig:
        """Build and validate from a flat mapping (e.g. a merged ROS params file)."""
        return from_mapping(cls, values, strict=strict)

    def reference(self, x, y, yaw, curvature, speed) -> Reference:
        """The MPC's :class:`Reference` of path arrays (a ReferenceTrajectory's) with this
        config's nearest-point window: the one way the node and the in-process loop build
        it."""
        return Reference.from_arrays(x, y, yaw, curvature, speed,
                                     search_back=self.ref_search_back,
                                     search_ahead=self.ref_search_ahead)

    def model_params(self) -> ModelParams:
        """Parameters of eq. (1) in SI."""
        return ModelParams(
            mass_kg=self.mass_kg, yaw_inertia_kg_m2=self.yaw_inertia_kg_m2,
            a_m=self.cg_to_front_axle_m, b_m=self.cg_to_rear_axle_m,
            c_cf=self.cornering_stiffness_front_static_n_per_rad,
            c_cr=self.cornering_stiffness_rear_static_n_per_rad,
            c_lf=self.longitudinal_stiffness_front_n, c_lr=self.longitudinal_stiffness_rear_n,
            slip_front=self.slip_ratio_front, slip_rear=self.slip_ratio_rear,
            min_speed_mps=self.min_speed_mps,
            steer_front_time_constant_s=self.steer_front_time_constant_s,
            steer_rear_time_constant_s=self.steer_rear_time_constant_s,
            relaxation_length_front_m=self.relaxation_length_front_m,
            relaxation_length_rear_m=self.relaxation_length_rear_m,
            gravity_mps2=self.gravity_mps2, track_width_m=self.track_width_m,
            tyre_shape_lateral=self.tyre_shape_lateral,
            tyre_curvature_lateral=self.tyre_curvature_lateral,
            cg_height_m=self.cg_height_m,
            roll_stiffness_front_share=self.roll_stiffness_front_share,
            tyre_stiffness_peak_load_n=self.tyre_cornering_load_factor * self.tyre_nominal_load_n)

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
                lo, hi = clamp_nc(self.nc_min, n_p), clamp_nc(self.nc_max, n_p)
                pairs.update((n_p, n_c) for n_c in range(lo, hi + 1))
        return sorted(pairs)

    def fuzzy_spec(self) -> FuzzySpec:
        """Universes and grid of the fuzzy scheduler."""
        return FuzzySpec(self.fuzzy_e_y_range_m, self.fuzzy_e_phi_range_deg,
                         self.fuzzy_grid_y, self.fuzzy_grid_phi, self.fuzzy_out_points)
