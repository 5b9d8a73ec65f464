"""Runs ``lqr_ff``, the textbook lateral controller (``core.lqr``), behind the MPC's interface.

Same inputs and outputs as :class:`~fourws_mpc.core.controller.MpcController` (a
:class:`VehicleSample`, the reference, an :class:`MpcResult`), so the node, the in-process
loop and the recorder treat it as one more preset
(docs/mpc.md, "The textbook reference `lqr_ff`"). One step:

1. errors at the nearest point (the MPC's own ``Reference``): e1 = e_Y, e2 = e_φ,
   ė1 = v_y + v_x e2, ė2 = r − v_x κ (Rajamani sec. 2.5, linearised);
2. δ = −K(v_x) x + δ_ff(κ, v_x) (``core.lqr``);
3. the same actuator limits the MPC respects: |δ| ≤ max_steer_front_deg and
   |δ(k) − δ(k−1)| ≤ max_dsteer_front_deg (the steering actuator's rate limit); δ_r ≡ 0 and
   M_z ≡ 0 (front steer only; the preset allocates the torque equally).

With known delays (``input_delay_periods``, ``steer_dead_time_s``) step 1 uses the state
predicted over the delay N_d exactly as the MPC does (``core.delay``, Autoware's scheme): the
path-frame state ζ0 of the MPC's prediction model (``prediction_model``,
``prediction_discretisation``) advanced N_d periods with the commands already sent, and the
errors taken against the reference N_d periods ahead: e1 = Y_d − Y_ref(N_d),
e2 = φ_d − φ_ref(N_d), ė1 = v_y,d + v_x e2, ė2 = r_d − v_x κ. Without delays this is step 1
as written (ζ0's Y and φ are e_Y and e_φ).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from fourws_mpc.core.config import MpcConfig
from fourws_mpc.core.controller import MpcController, MpcResult, VehicleSample, initial_state
from fourws_mpc.core.delay import (
    CommandBuffer,
    channel_delays,
    predict_over_delay,
    register_schedule,
)
from fourws_mpc.core.lqr import LqrLateral, LqrWeights
from fourws_mpc.core.model import N_INPUT, InputIdx, StateIdx
from fourws_mpc.core.prediction_model import make_prediction_model
from fourws_mpc.core.reference import PathErrors, Reference


def lqr_weights(c: MpcConfig) -> LqrWeights:
    """Bryson's maxima of the config in SI."""
    return LqrWeights(c.lqr_e1_max_m, c.lqr_e1_dot_max_mps, math.radians(c.lqr_e2_max_deg),
                      math.radians(c.lqr_e2_dot_max_deg_s), math.radians(c.lqr_steer_max_deg))


class LqrFfController:
    """Front-steer LQR with curvature feed-forward (module docstring)."""

    def __init__(self, cfg: MpcConfig | None = None) -> None:
        self.cfg = cfg if cfg is not None else MpcConfig(law="lqr_ff")
        self._build(self.cfg)
        self.reset()

    def _build(self, c: MpcConfig) -> None:
        """The law, the limits, the delays and the model of ``c``; what can raise is built
        first, so a config that fails here changes nothing."""
        mp = c.model_params()
        law = LqrLateral(mp, c.dt_s, lqr_weights(c))
        model = make_prediction_model(c.prediction_model, mp, c.prediction_discretisation)
        delays = channel_delays(c.input_delay_periods, c.steer_dead_time_s, c.dt_s)
        self.law, self.model = law, model
        self._d_max = math.radians(c.max_steer_front_deg)
        self._dd_max = math.radians(c.max_dsteer_front_deg)
        self._delays = delays
        self._n_delay = max(delays)
        self._schedule = register_schedule(delays)

    def update_config(self, cfg: MpcConfig) -> None:
        """New constants, the last command and the reference index kept; a config that
        fails to build changes nothing."""
        if cfg != self.cfg:
            forget = cfg.prediction_model != self.cfg.prediction_model
            self._build(cfg)
            if forget:
                self.model_memory = None
            self.cfg = cfg
            self.sent = self.sent.resized(self._n_delay)

    def reset(self, u_prev: np.ndarray | None = None) -> None:
        """Forget the last command and the reference index."""
        u = np.zeros(N_INPUT) if u_prev is None else np.asarray(u_prev, float).reshape(N_INPUT)
        if not np.all(np.isfinite(u)):
            raise ValueError(f"u_prev: not finite ({u_prev!r}); nothing was reset")
        self.u_prev = np.array([min(max(u[InputIdx.DF], -self._d_max), self._d_max), 0.0, 0.0])
        self.sent = CommandBuffer(self._n_delay, self.u_prev)
        self.ref_hint: int | None = None
        self._ref: Reference | None = None
        self.model_memory = None

    def adopt_reference(self, ref: Reference) -> None:
        """Use ``ref`` from the next step on, keeping the nearest-point index."""
        if self._ref is not None:
            self._ref = ref

    def step(self, t_s: float, state: VehicleSample, ref: Reference, mu: float | None = None
             ) -> MpcResult:
        """One control period; ``mu`` is not used (the law knows no road)."""
        s = MpcController._read_state(state, mu)
        hint = self.ref_hint if ref is self._ref else None
        err = ref.errors(s.x, s.y, s.yaw, hint)
        kappa = err.near.curvature
        x, memory = self._error_state(s, ref, err)
        d = self.law.steer(x, s.vx, kappa)
        prev = float(self.u_prev[InputIdx.DF])
        d = min(max(d, prev - self._dd_max), prev + self._dd_max)
        d = min(max(d, -self._d_max), self._d_max)
        self.u_prev = np.array([d, 0.0, 0.0])
        self.sent.push(self.u_prev)
        self.model_memory = memory
        self._ref, self.ref_hint = ref, err.near.index
        return MpcResult(
            delta_front=d, delta_rear=0.0, yaw_moment=0.0, controller=self.cfg.controller,
            np=0, nc=0, q_y=0.0, q_phi=0.0, r_ddelta=0.0, r_dmz=0.0,
            lateral_error=float(err.lateral_error), heading_error=float(err.heading_error),
            e_s=0.0, k_e=0.0, k_u=0.0,
            solver_status="lqr", iterations=0, slack=0.0, fallback=False,
            ref_index=err.near.index, ref_speed=err.near.speed)

    def _error_state(self, s: VehicleSample, ref: Reference, err: PathErrors
                     ) -> tuple[np.ndarray, Any]:
        """x = [e1, ė1, e2, ė2] now, or predicted over the known delay (module docstring);
        and the prediction model's memory for the next step."""
        kappa = err.near.curvature
        if not self._n_delay:
            e1, e2 = err.lateral_error, err.heading_error
            return np.array([e1, s.vy + s.vx * e2, e2, s.yaw_rate - s.vx * kappa]), None
        c = self.cfg
        zeta, memory = initial_state(self.model, s, ref, err.near, "path", self.model_memory,
                                     c.dt_s)
        Ak, Bk, dk = self.model.discretise(zeta, self.u_prev, c.dt_s)
        z = predict_over_delay(Ak, Bk, dk, zeta, self.sent.applied(self._schedule))
        phi_ref, y_ref = ref.horizon(err.near, s.vx, c.dt_s, self._n_delay, s.yaw, "path")
        e1 = z[StateIdx.Y] - y_ref[-1]
        e2 = z[StateIdx.PHI] - phi_ref[-1]
        return (np.array([e1, z[StateIdx.VY] + s.vx * e2, e2, z[StateIdx.R] - s.vx * kappa]),
                memory)
