"""``lqr_ff``: the textbook lateral controller (``core.lqr``) behind the MPC's interface.

Same inputs and outputs as :class:`~fourws_mpc.core.controller.MpcController` (a
:class:`VehicleSample`, the reference, an :class:`MpcResult`), so the node, the in-process
loop and the recorder treat it as one more preset. One step:

1. errors at the nearest point (the MPC's own ``Reference``): e1 = e_Y, e2 = e_φ,
   ė1 = v_y + v_x e2, ė2 = r − v_x κ (Rajamani sec. 2.5, linearised);
2. δ = −K(v_x) x + δ_ff(κ, v_x) (``core.lqr``);
3. the same actuator limits the MPC respects: |δ| ≤ max_steer_front_deg and
   |δ(k) − δ(k−1)| ≤ max_dsteer_front_deg (the steering actuator's rate limit); δ_r ≡ 0 and
   M_z ≡ 0 (front steer only; the preset allocates the torque equally).
"""

from __future__ import annotations

import math

import numpy as np

from fourws_mpc.core.config import MpcConfig
from fourws_mpc.core.controller import MpcController, MpcResult, VehicleSample
from fourws_mpc.core.lqr import LqrLateral, LqrWeights
from fourws_mpc.core.model import N_INPUT, InputIdx
from fourws_mpc.core.reference import Reference


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
        self.law = LqrLateral(c.model_params(), c.dt_s, lqr_weights(c))
        self._d_max = math.radians(c.max_steer_front_deg)
        self._dd_max = math.radians(c.max_dsteer_front_deg)

    def update_config(self, cfg: MpcConfig) -> None:
        """New constants, the last command and the reference index kept."""
        if cfg != self.cfg:
            self.cfg = cfg
            self._build(cfg)

    def reset(self, u_prev: np.ndarray | None = None) -> None:
        """Forget the last command and the reference index."""
        u = np.zeros(N_INPUT) if u_prev is None else np.asarray(u_prev, float).copy()
        self.u_prev = np.array([min(max(u[InputIdx.DF], -self._d_max), self._d_max), 0.0, 0.0])
        self.ref_hint: int | None = None
        self._ref: Reference | None = None

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
        e1, e2 = err.lateral_error, err.heading_error
        kappa = err.near.curvature
        x = np.array([e1, s.vy + s.vx * e2, e2, s.yaw_rate - s.vx * kappa])
        d = self.law.steer(x, s.vx, kappa)
        prev = float(self.u_prev[InputIdx.DF])
        d = min(max(d, prev - self._dd_max), prev + self._dd_max)
        d = min(max(d, -self._d_max), self._d_max)
        self.u_prev = np.array([d, 0.0, 0.0])
        self._ref, self.ref_hint = ref, err.near.index
        return MpcResult(
            delta_front=d, delta_rear=0.0, yaw_moment=0.0, controller=self.cfg.controller,
            np=0, nc=0, q_y=0.0, q_phi=0.0, r_ddelta=0.0, r_dmz=0.0,
            lateral_error=float(e1), heading_error=float(e2), e_s=0.0, k_e=0.0, k_u=0.0,
            solver_status="lqr", iterations=0, slack=0.0, fallback=False,
            ref_index=err.near.index, ref_speed=err.near.speed)
