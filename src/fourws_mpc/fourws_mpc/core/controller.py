"""Runs one step of the MPC of section 3 as named stages, and falls back when the solve fails.

One call of :meth:`MpcController.step` at time k, stage by stage (docs/mpc.md, "Public API"):

1. **read state** (:meth:`~MpcController._read_state`): the measured :class:`VehicleSample`
   and μ, checked finite and plausible (:data:`fourws_common.input_guard.STATE_LIMITS`);
   a bad one raises ``ValueError`` before anything changes;
2. **errors**: nearest point on the reference and e_Y (m, left +), e_φ (rad) (``reference``);
3. **weights**: fixed (Q_φ, Q_Y, R_Δδ, R_ΔMz from the config) or fuzzy (section 3.2,
   ``fuzzy_weights``) from (e_Y, e_φ);
4. **horizons**: fixed (N_p, N_c baseline) or APCHA (eq. 7-15, ``apcha``);
5. **prediction**: ζ0 = [vy, vx, φ, r, Y, X] in the path frame at the nearest point
   (``prediction_frame = "path"``; "global": the paper's map frame), extended by the model's
   own states (an observer's memory is committed in stage 7), the reference outputs
   (φ_ref, Y_ref) at s + vx T i, i = 1..N_p, and the injected prediction model
   (``prediction_model``) discretised at (ζ0, u(k−1)), eq. (4). With known delays ζ0 is
   predicted over the delay N_d with the commands already sent and the reference starts N_d
   periods later (``delay``);
6. **solve**: the QP of eq. (16)-(20) (``qp``) with the injected solver (``qp_solver``),
   warm-started from the previous plan shifted by one, the paper's weights through
   ``cost_scaling`` and, with ``terminal_cost: lqr``, the LQR cost-to-go (``terminal_cost``);
   hard bounds |vy| ≤ vx tan β_max and |r| ≤ factor μ g / vx on predicted steps
   i ≥ ``state_bounds_from_step``, each relaxed to the current |vy| or |r| when the car is
   already beyond it; a QP still infeasible is solved again without them
   (:data:`STATE_BOUNDS_DROPPED`);
7. **result**: u(k) = u(k−1) + Δu*(k), eq. (22), or the fallback; the step's history (with
   the buffer of commands sent) is committed only here.

Fallback (docs/mpc.md, "Solver"): without a trusted solution (``qp_solver.trusted``; or a QP
infeasible because of the hard bounds) the previous optimal plan is applied shifted by one
step (u(k|k−1), then u(k+1|k−2), ...), and the last command is held once it is used up or
absent. The result is flagged ``fallback`` and is always finite; QP data a solver would
refuse are a failed solve, never handed over. The core never reads a clock.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from fourws_common.input_guard import implausible_fields
from fourws_mpc.core.apcha import apcha, input_rate, integrated_error
from fourws_mpc.core.config import MpcConfig
from fourws_mpc.core.cost_scaling import effective_weights, level_weights
from fourws_mpc.core.delay import (
    CommandBuffer,
    channel_delays,
    predict_over_delay,
    register_schedule,
)
from fourws_mpc.core.friction_model import Grip
from fourws_mpc.core.fuzzy_weights import FuzzyWeights
from fourws_mpc.core.grip import (
    GripEstimate,
    GripEstimator,
    GripMemory,
    GripSettings,
    peak_slips,
    steer_window,
    yaw_moment_bound,
)
from fourws_mpc.core.model import N_INPUT, N_STATE, InputIdx, StateIdx
from fourws_mpc.core.prediction_model import PredictionModel, make_prediction_model
from fourws_mpc.core.qp import MpcQp, QpBounds, QpSolution, unconstrained_gain
from fourws_mpc.core.qp_solver import QpSettings, QpSolver, QpStatus, make_qp_solver
from fourws_mpc.core.reference import NearestPoint, Reference
from fourws_mpc.core.terminal_cost import TerminalWeight

#: appended to the solver status when the QP was solved without the hard state bounds
STATE_BOUNDS_DROPPED = "hard state bounds dropped (infeasible with them)"
#: a delivered yaw moment this close to the command (N·m) is the allocator's round-off
DELIVERED_ROUNDING_NM = 1e-6
#: in the solver status when ``terminal_cost: lqr`` found no stabilising DARE solution at
#: this step (the QP is then solved without the terminal cost)
TERMINAL_COST_SKIPPED = "terminal cost skipped (no stabilising DARE solution)"


@dataclass(frozen=True, slots=True)
class VehicleSample:
    """The measured state the MPC takes (SI, map frame / ISO body frame): its one state type.
    :meth:`of` builds it from anything with these attributes (a VehicleState message, the
    plant's outputs). ``steer_front``, ``steer_rear`` are the actual road-wheel angles (rad),
    read only by a prediction model with actuator states."""

    x: float
    y: float
    yaw: float
    vx: float
    vy: float
    yaw_rate: float
    steer_front: float = 0.0
    steer_rear: float = 0.0
    ax: float = 0.0
    ay: float = 0.0

    @classmethod
    def of(cls, obj: Any) -> VehicleSample:
        """The sample of an object with attributes x, y, yaw, vx, vy, yaw_rate, steer_front,
        steer_rear and, if it has them, the measured accelerations ax, ay (m/s²; read by
        the friction-aware model's μ estimate)."""
        return cls(float(obj.x), float(obj.y), float(obj.yaw), float(obj.vx), float(obj.vy),
                   float(obj.yaw_rate), float(obj.steer_front), float(obj.steer_rear),
                   float(getattr(obj, "ax", 0.0)), float(getattr(obj, "ay", 0.0)))


#: the fields of :class:`VehicleSample`, in order (what a node reads from its state message)
MEAS_FIELDS = tuple(f.name for f in dataclasses.fields(VehicleSample))


# the stages' records: named tuples (immutable, and built at a fraction of a frozen
# dataclass's cost, several times a step)
class _Errors(NamedTuple):
    near: NearestPoint
    e_y: float
    e_phi: float


class _Horizons(NamedTuple):
    n_p: int
    n_c: int
    e_s: float
    k_e: float
    k_u: float


class _Weights(NamedTuple):
    q_y: float
    q_phi: float
    r_ddelta: float
    r_dmz: float


class _GripStep(NamedTuple):
    """Stage 5's grip (friction-aware model only): μ̂, its memory, and the envelope."""

    estimate: GripEstimate
    memory: GripMemory
    beta_max_rad: float
    mz_max_nm: float
    u_min: np.ndarray
    u_max: np.ndarray


class _Prediction(NamedTuple):
    zeta: np.ndarray
    ref_out: np.ndarray
    Ak: np.ndarray
    Bk: np.ndarray
    dk: np.ndarray
    memory: Any = None
    grip: _GripStep | None = None


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
    #: μ the step assumed (the friction-aware model's estimate; else the state's or
    #: mu_default) and the |M_z| bound it applied (N·m)
    mu_estimate: float = math.nan
    yaw_moment_bound: float = math.nan
    grip_note: str = ""


@njit(cache=True)
def _clamp_enabled(u: np.ndarray, enabled: np.ndarray, lo: np.ndarray, hi: np.ndarray
                   ) -> np.ndarray:
    """u clipped to [lo, hi] per input, 0 where the input is disabled (a new array; u
    finite, lo ≤ hi)."""
    out = np.zeros(u.shape[0])
    for i in range(u.shape[0]):
        if enabled[i]:
            out[i] = min(max(u[i], lo[i]), hi[i])
    return out


def initial_state(model: PredictionModel, s: VehicleSample, ref: Reference,
                  near: NearestPoint, frame: str = "path", memory: Any = None,
                  dt_s: float = 0.0) -> tuple[np.ndarray, Any]:
    """ζ0 = [vy, vx, φ, r, Y, X] in the prediction frame (the path frame at ``near``, or the
    map frame for ``global``), extended by the model's own measured and estimated states, and
    the model's memory for the next step (``PredictionModel.measured_state``; ``memory`` is
    the previous step's, ``dt_s`` the time since it)."""
    zeta = np.zeros(N_STATE)
    zeta[StateIdx.VY], zeta[StateIdx.VX], zeta[StateIdx.R] = s.vy, s.vx, s.yaw_rate
    X, Y, phi = (ref.to_path_frame(near, s.x, s.y, s.yaw) if frame == "path"
                 else (s.x, s.y, s.yaw))
    zeta[StateIdx.PHI], zeta[StateIdx.Y], zeta[StateIdx.X] = phi, Y, X
    return model.measured_state(zeta, s.steer_front, s.steer_rear, memory, dt_s)


class MpcController:
    """Section 3's MPC; one instance per vehicle. Stateful: previous input, plan, horizons.

    ``model`` and ``solver`` inject a prediction model (:class:`PredictionModel`) and a QP
    solver (:class:`QpSolver`); by default they are the ones the config names
    (``prediction_model``, ``qp_solver``).
    """

    def __init__(self, cfg: MpcConfig | None = None, *, model: PredictionModel | None = None,
                 solver: QpSolver | None = None) -> None:
        self.cfg = cfg if cfg is not None else MpcConfig()
        self.fuzzy: FuzzyWeights | None = None
        self._injected_model = model
        self._injected_solver = solver
        self._apply(self.cfg, None)
        self._stepped = False
        self.reset()

    @staticmethod
    def _qp_settings(c: MpcConfig) -> QpSettings:
        return QpSettings(eps_abs=c.osqp_eps_abs, eps_rel=c.osqp_eps_rel,
                          max_iter=c.qp_max_iter, polishing=c.osqp_polishing,
                          accept_inaccurate=c.osqp_accept_inaccurate,
                          check_termination=c.osqp_check_termination)

    def _new_qp(self, c: MpcConfig, settings: QpSettings) -> MpcQp:
        """A fresh QP and solver state (an injected solver is reset; it keeps its own
        settings); every reachable (N_p, N_c) set up if prebuilding."""
        solver = self._injected_solver
        if solver is not None:
            solver.reset()
        qp = MpcQp(settings, solver if solver is not None else
                   make_qp_solver(c.qp_solver, settings))
        if c.qp_prebuild:
            for n_p, n_c in c.horizon_pairs():
                qp.instance(n_p, n_c)
        return qp

    def _apply(self, c: MpcConfig, old: MpcConfig | None) -> None:
        """Derive everything that depends on the config; rebuild only what changed. What can
        raise is built first: a config that fails here changes nothing."""
        mp = c.model_params()
        model = (self._injected_model if self._injected_model is not None else
                 make_prediction_model(c.prediction_model, mp, c.prediction_discretisation))
        keep_fuzzy = (self.fuzzy is not None and old is not None
                      and c.fuzzy_spec() == old.fuzzy_spec())
        fuzzy = (None if c.weights_mode != "fuzzy" else
                 self.fuzzy if keep_fuzzy else FuzzyWeights(c.fuzzy_spec()))
        grip = (GripEstimator(mp, GripSettings(
            prior=c.mu_default, floor=c.mu_floor, ceiling=c.mu_ceiling,
            evidence_deficit=c.mu_evidence_deficit, evidence_max_ax=c.mu_evidence_max_ax,
            evidence_min_ask=c.mu_evidence_min_ask,
            evidence_min_speed=c.mu_evidence_min_speed_mps, fall_time_s=c.mu_fall_time_s,
            rise_time_s=c.mu_rise_time_s))
            if getattr(model, "grip_aware", False) else None)
        delays = channel_delays(c.input_delay_periods, c.steer_dead_time_s, c.dt_s)
        settings = self._qp_settings(c)
        if old is None or settings != self.qp.settings or c.qp_solver != old.qp_solver:
            qp = self._new_qp(c, settings)
        else:
            qp = self.qp
            if c.qp_prebuild:
                for n_p, n_c in c.horizon_pairs():
                    qp.instance(n_p, n_c)
        # commit
        if old is not None and c.prediction_model != old.prediction_model:
            self.model_memory = None            # another model's estimate means nothing
        self.model, self.fuzzy, self._grip, self.qp = model, fuzzy, grip, qp
        self._delays = delays
        self._n_delay = max(delays)
        self._schedule = register_schedule(delays)
        self.apcha_params = c.apcha_params()
        self._du_max = c.du_max
        self._u_max = c.u_max
        self._enabled = c.enabled
        self._gravity = mp.gravity_mps2

    def update_config(self, cfg: MpcConfig) -> None:
        """Apply a new configuration to the running controller without losing its state.

        u(k−1), the last increment, the stored plan, the horizons (clamped into the new
        APCHA range, or the new baseline in fixed mode), e_s(k−1) and the reference index are
        kept; the fuzzy surface and the solver are rebuilt only if their own settings
        changed. An equal config is a no-op.
        """
        old = self.cfg
        if cfg == old:
            return
        self._apply(cfg, old)
        self.cfg = cfg
        self.u_prev = _clamp_enabled(self.u_prev, self._enabled, -self._u_max, self._u_max)
        if cfg.horizons_mode == "apcha":
            self.n_p = min(max(self.n_p, cfg.np_min), cfg.np_max)
            self.n_c = min(max(self.n_c, cfg.nc_min), cfg.nc_max, self.n_p)
        else:
            self.n_p, self.n_c = cfg.np_baseline, cfg.nc_baseline
        self.sent = self.sent.resized(self._n_delay)
        self.sent.registers[0] = self.u_prev

    def report_delivered(self, yaw_moment_nm: float) -> None:
        """The yaw moment the lower layer delivered for the last command (its demand less
        what it could not meet): the next step starts from it, u(k−1) and the newest command
        sent, instead of from the one asked for. Within :data:`DELIVERED_ROUNDING_NM` of the
        command it is the allocator's round-off and changes nothing (the graph and the
        in-process loop then agree bit for bit). Non-finite: ``ValueError``, nothing
        changes."""
        mz = float(yaw_moment_nm)
        if not math.isfinite(mz):
            raise ValueError(f"delivered yaw moment: not finite ({yaw_moment_nm!r})")
        if abs(mz - self.u_prev[InputIdx.MZ]) <= DELIVERED_ROUNDING_NM:
            return                          # the allocator's round-off, not a shortfall
        lim = float(self._u_max[InputIdx.MZ]) if self._enabled[InputIdx.MZ] else 0.0
        self.u_prev = self.u_prev.copy()
        self.u_prev[InputIdx.MZ] = min(max(mz, -lim), lim)
        self.sent.registers[0] = self.u_prev

    def adopt_reference(self, ref: Reference) -> None:
        """Use ``ref`` (the same path, e.g. with another search window) from the next step on
        and keep the nearest-point index, instead of a global search as for a new path."""
        if self._ref is not None:
            self._ref = ref

    def reset(self, u_prev: np.ndarray | None = None) -> None:
        """Forget the past: u(k−1) (default zeros), plan, horizons, reference index, and the
        solver's internal state (OSQP keeps its adapted ρ and duals between solves), so a
        reset controller answers exactly as a new one."""
        u = np.zeros(N_INPUT) if u_prev is None else np.asarray(u_prev, float).reshape(N_INPUT)
        if not np.all(np.isfinite(u)):
            raise ValueError(f"u_prev: not finite ({u_prev!r}); nothing was reset")
        if self._stepped:
            self.qp = self._new_qp(self.cfg, self.qp.settings)
            self._stepped = False
        self.u_prev = _clamp_enabled(u, self._enabled, -self._u_max, self._u_max)
        self.sent = CommandBuffer(self._n_delay, self.u_prev)
        self.du_last = np.zeros(N_INPUT)
        self.plan_u: np.ndarray | None = None
        self.plan_du_scaled: np.ndarray | None = None
        self.plan_pos = 0
        self.n_p = self.cfg.np_baseline
        self.n_c = self.cfg.nc_baseline
        self.e_s_prev: float | None = None
        self.ref_hint: int | None = None
        self._ref: Reference | None = None
        self.model_memory: Any = None
        self.grip_memory: GripMemory | None = None
        self.terminal = TerminalWeight()

    def step(self, t_s: float, state: VehicleSample, ref: Reference, mu: float | None = None
             ) -> MpcResult:
        """One control period, in the stages of the module docstring.

        t_s: time of the state (s, for the record only); state: the measured state (SI);
        ref: the reference path; mu: road adhesion, the state's (ignored unless
        ``mu_from_state``; None: estimated by the friction-aware model, else ``mu_default``).
        """
        meas = self._read_state(state, mu)
        if not self.cfg.mu_from_state:
            mu = None                       # a car measures no μ: estimated, or mu_default
        self._stepped = True
        err = self._errors(meas, ref)
        w = self._weights(err)
        hz = self._horizons(err)
        pred = self._prediction(meas, ref, err, hz, mu)
        sol = self._solve(meas, mu, pred, hz, w)
        return self._result(ref, err, w, hz, sol, pred, mu)

    # -- stages ---------------------------------------------------------------------------
    @staticmethod
    def _read_state(state: VehicleSample, mu: float | None) -> VehicleSample:
        """Stage 1: the state and μ, finite and within STATE_LIMITS, else ``ValueError``."""
        if not isinstance(state, VehicleSample):
            raise TypeError(f"state: a VehicleSample, got {type(state).__name__} "
                            "(VehicleSample.of(obj) builds one)")
        # non-finite, or finite but absurd (x = 1e300: it would overflow the projection and
        # the QP): the same rule as the nodes' input guard
        bad = implausible_fields(state, MEAS_FIELDS)
        if bad:
            raise ValueError(f"state: not finite or implausible: {', '.join(bad)}")
        if mu is not None and not math.isfinite(mu):
            raise ValueError(f"mu: not finite ({mu!r})")
        return state

    def _errors(self, s: VehicleSample, ref: Reference) -> _Errors:
        """Stage 2: nearest point (searched around the last one on the same path)."""
        hint = self.ref_hint if ref is self._ref else None
        err = ref.errors(s.x, s.y, s.yaw, hint)
        return _Errors(err.near, err.lateral_error, err.heading_error)

    def _weights(self, err: _Errors) -> _Weights:
        """Stage 3: fixed weights, or eq. (23) with the fuzzy ratios."""
        c = self.cfg
        if self.fuzzy is None:
            return _Weights(c.q_y, c.q_phi, c.r_ddelta, c.r_dmz)
        r = self.fuzzy.ratios(err.e_y, err.e_phi)
        return _Weights(float(r[0] * c.q_y_max), float(r[1] * c.q_phi_max),
                        float(r[2] * c.r_ddelta_max), float(r[3] * c.r_dmz_max))

    def _horizons(self, err: _Errors) -> _Horizons:
        """Stage 4: APCHA (eq. 7-15), or the baseline with k_e, k_u for the record."""
        c = self.cfg
        e_s = integrated_error(err.e_y, err.e_phi, self.apcha_params)
        if c.horizons_mode == "apcha":
            h = apcha(e_s, self.e_s_prev, self.du_last, self.n_p, self.n_c, self.apcha_params)
            return _Horizons(h.n_p, h.n_c, e_s, h.k_e, h.k_u)
        k_e = 0.0 if self.e_s_prev is None else abs(e_s - self.e_s_prev) / c.dt_s
        k_u = input_rate(self.du_last, self.apcha_params)
        return _Horizons(c.np_baseline, c.nc_baseline, e_s, k_e, k_u)

    def _prediction(self, s: VehicleSample, ref: Reference, err: _Errors, hz: _Horizons,
                    mu: float | None) -> _Prediction:
        """Stage 5: ζ0 in the prediction frame (with the model's appended states); with the
        friction-aware model the grip (μ̂ and its envelope, ``grip``); eq. (4) at ζ0; with
        known delays ζ0 predicted over them (``delay``); the reference outputs from the
        delayed point on."""
        c = self.cfg
        zeta, memory = initial_state(self.model, s, ref, err.near, c.prediction_frame,
                                     self.model_memory, c.dt_s)
        grip = None if self._grip is None else self._grip_step(zeta, s, mu)
        n_d = self._n_delay
        phi_ref, y_ref = ref.horizon(err.near, s.vx, c.dt_s, hz.n_p + n_d, s.yaw,
                                     c.prediction_frame)
        Ak, Bk, dk = self.model.discretise(zeta, self.u_prev, c.dt_s)
        if n_d:
            zeta = predict_over_delay(Ak, Bk, dk, zeta, self.sent.applied(self._schedule))
        ref_out = np.empty((hz.n_p, 2))
        ref_out[:, 0], ref_out[:, 1] = phi_ref[n_d:], y_ref[n_d:]
        return _Prediction(zeta, ref_out, Ak, Bk, dk, memory, grip)

    def _grip_step(self, zeta: np.ndarray, s: VehicleSample, mu: float | None) -> _GripStep:
        """μ̂ (``grip``), the model's road for this step, and the envelope it gives."""
        c, p = self.cfg, self.model.params
        mz = float(self.u_prev[InputIdx.MZ])
        est, mem = self._grip.estimate(zeta, s.ax, s.ay, mz, mu, self.grip_memory, c.dt_s)
        lim = c.mu_ceiling * self._gravity    # the loads' accelerations: no road gives more
        ax = min(max(s.ax, -lim), lim)
        self.model.grip = Grip(est.mu, ax, min(max(s.ay, -lim), lim))
        vxb = max(s.vx, c.min_speed_mps)
        r_max = c.yaw_rate_mu_factor * est.mu * self._gravity / vxb
        peaks = peak_slips(p, est.mu)
        beta = min(math.radians(c.max_sideslip_deg), peaks[1] + p.b_m * r_max / vxb)
        mz_max = min(c.max_yaw_moment_nm, yaw_moment_bound(zeta, p, est.mu, ax))
        lo, hi = -self._u_max, self._u_max.copy()       # negation is a new array
        hi[InputIdx.MZ] = mz_max
        lo[InputIdx.MZ] = -mz_max
        w_lo, w_hi = steer_window(s.vx, s.vy, s.yaw_rate, p, est.mu, peaks)
        for i, ch in enumerate((InputIdx.DF, InputIdx.DR)):
            if self._enabled[ch]:            # a pinned input keeps its bounds around 0
                lo[ch] = min(max(w_lo[i], lo[ch]), hi[ch])
                hi[ch] = max(min(w_hi[i], hi[ch]), lo[ch])
        # reachable from u(k−1) within one increment: the QP stays feasible
        lo = np.minimum(lo, self.u_prev + self._du_max)
        hi = np.maximum(hi, self.u_prev - self._du_max)
        return _GripStep(est, mem, beta, mz_max, lo, hi)

    def _solve(self, s: VehicleSample, mu: float | None, pred: _Prediction, hz: _Horizons,
               w: _Weights) -> QpSolution:
        """Stage 6: bounds of eq. (20), the scaled weights, the QP."""
        c = self.cfg
        vxb = max(s.vx, c.min_speed_mps)
        mu_b = self._mu_bound(mu)
        beta_max, u_max = math.radians(c.max_sideslip_deg), self._u_max
        if pred.grip is not None:          # the envelope of the estimated grip
            mu_b, beta_max = pred.grip.estimate.mu, pred.grip.beta_max_rad
        vy_max = vxb * math.tan(beta_max)
        r_max = c.yaw_rate_mu_factor * mu_b * self._gravity / vxb
        if pred.grip is None:
            # hard bounds "no worse than now": where the QP starts, i.e. after a compensated
            # delay (the friction-aware envelope is soft: its slack keeps the QP feasible)
            vy_max = max(vy_max, abs(s.vy), abs(pred.zeta[StateIdx.VY]))
            r_max = max(r_max, abs(s.yaw_rate), abs(pred.zeta[StateIdx.R]))
        bounds = QpBounds(
            du_max=self._du_max, u_max=u_max if pred.grip is None else pred.grip.u_max,
            u_min=None if pred.grip is None else pred.grip.u_min, enabled=self._enabled,
            vy_max=vy_max, r_max=r_max,
            state_softness=0.0 if pred.grip is None else c.envelope_softness,
            band_phi=math.radians(c.soft_band_phi_deg), band_y=c.soft_band_y_m,
            state_bounds=c.state_bounds, state_bounds_from_step=c.state_bounds_from_step)
        q_eff, r_eff, s_level, terminal_w, note = self._cost(w, pred.Ak, pred.Bk)
        sol = self.qp.solve(pred.Ak, pred.Bk, pred.dk, pred.zeta, self.u_prev, pred.ref_out,
                            hz.n_p, hz.n_c, q_eff, r_eff, c.rho, bounds,
                            warm_du_scaled=self._warm(hz.n_c), s_level=s_level,
                            terminal_w=terminal_w)
        sol.status += note
        if sol.ok or sol.code is not QpStatus.PRIMAL_INFEASIBLE or not bounds.state_bounds:
            return sol
        # the hard bounds cannot be met from here (the lagging steering still moves the
        # state after the start): solve without them rather than fall back blind
        retry = self.qp.solve(pred.Ak, pred.Bk, pred.dk, pred.zeta, self.u_prev,
                              pred.ref_out, hz.n_p, hz.n_c, q_eff, r_eff, c.rho,
                              dataclasses.replace(bounds, state_bounds=False),
                              warm_du_scaled=self._warm(hz.n_c), s_level=s_level,
                              terminal_w=terminal_w)
        if retry.ok:
            retry.status = f"{retry.status}, {STATE_BOUNDS_DROPPED}{note}"
            return retry
        return sol

    def _mu_bound(self, mu: float | None) -> float:
        """μ of the yaw-rate bound without the friction-aware model: the state's (floored at
        0.01), else ``mu_default``."""
        return self.cfg.mu_default if mu is None else max(float(mu), 0.01)

    def _cost(self, w: _Weights, Ak: np.ndarray, Bk: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, str]:
        """The cost of stage 6: the scaled weights (``cost_scaling``), the level weights and
        the terminal weight (``terminal_cost``; None and a note when it cannot be had)."""
        c = self.cfg
        q_eff, r_eff = effective_weights(c, w.q_phi, w.q_y, w.r_ddelta, w.r_dmz)
        s_level = level_weights(c, r_eff)
        terminal_w, note = None, ""
        if c.terminal_cost == "lqr":
            try:
                terminal_w = self.terminal(Ak, Bk, self._enabled, q_eff, r_eff)
            except (ValueError, np.linalg.LinAlgError):
                note = f", {TERMINAL_COST_SKIPPED}"
        return q_eff, r_eff, s_level, terminal_w, note

    def linearisation(self, vx_mps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A_k, B_k, d_k) of eq. (4) at the straight-path operating point: the prediction
        model's state at v_x (its appended states from the measurement), u = 0."""
        zeta = np.zeros(N_STATE)
        zeta[StateIdx.VX] = vx_mps
        zeta, _ = self.model.measured_state(zeta, 0.0, 0.0)
        return self.model.discretise(zeta, np.zeros(N_INPUT), self.cfg.dt_s)

    def unconstrained_gain(self, vx_mps: float) -> np.ndarray:
        """K (3, n+3) of the step's first move Δu(k) = −K [ζ; u(k−1)] without bounds at the
        straight-path operating point (:meth:`linearisation`), with the weights stage 3 takes
        at zero error (the fuzzy centre rule) and the baseline horizons: the gain the
        stability margins linearise (``fourws_bringup.core.margins``; ``qp.unconstrained_gain``
        on the QP's own condensing)."""
        c = self.cfg
        Ak, Bk, dk = self.linearisation(vx_mps)
        w = self._weights(_Errors(None, 0.0, 0.0))
        q_eff, r_eff, s_level, terminal_w, _ = self._cost(w, Ak, Bk)
        return unconstrained_gain(Ak, Bk, dk, c.np_baseline, c.nc_baseline, q_eff, r_eff,
                                  self._du_max, self._enabled, s_level, terminal_w)

    def _result(self, ref: Reference, err: _Errors, w: _Weights, hz: _Horizons,
                sol: QpSolution, pred: _Prediction, mu: float | None) -> MpcResult:
        """Stage 7: u(k) (eq. 22) or the fallback; commit the step's history."""
        if sol.ok:
            u = sol.u[0].copy()
            self.plan_u = sol.u.copy()
            self.plan_du_scaled = sol.du_scaled.copy()
            self.plan_pos = 0
            fallback = False
        else:
            fallback = True
            u = self._fallback_input()
        u = _clamp_enabled(u, self._enabled, -self._u_max, self._u_max)
        g = pred.grip
        if g is not None and fallback:     # a held plan obeys the grip's bounds
            u = _clamp_enabled(u, self._enabled, g.u_min, g.u_max)
        # the step's history is committed only here: a step that raised changed nothing
        self.du_last = u - self.u_prev
        self.u_prev = u
        self.sent.push(u)
        self.n_p, self.n_c = hz.n_p, hz.n_c
        self.e_s_prev = hz.e_s
        self.model_memory = pred.memory
        if g is not None:
            self.grip_memory = g.memory
        self._ref, self.ref_hint = ref, err.near.index
        return MpcResult(
            delta_front=float(u[InputIdx.DF]), delta_rear=float(u[InputIdx.DR]),
            yaw_moment=float(u[InputIdx.MZ]), controller=self.cfg.controller,
            np=int(hz.n_p), nc=int(hz.n_c), q_y=w.q_y, q_phi=w.q_phi, r_ddelta=w.r_ddelta,
            r_dmz=w.r_dmz, lateral_error=float(err.e_y), heading_error=float(err.e_phi),
            e_s=float(hz.e_s), k_e=float(hz.k_e), k_u=float(hz.k_u),
            solver_status=sol.status, iterations=sol.iterations, slack=float(sol.slack),
            fallback=fallback, ref_index=err.near.index, ref_speed=err.near.speed,
            mu_estimate=self._mu_bound(mu) if g is None else g.estimate.mu,
            yaw_moment_bound=float(self._u_max[InputIdx.MZ]) if g is None else g.mz_max_nm,
            grip_note="" if g is None else g.estimate.note)

    # -- plan memory ----------------------------------------------------------------------
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
