"""Turns the paper's weights into the QP's effective weights, one scaling for every controller.

The paper's weights multiply *normalised* channels, each divided by a characteristic size
(docs/mpc.md, "Cost scaling")::

    J = Σ_i Q_φ (e_φ,i / s_φ)² + Q_Y (e_Y,i / s_Y)²
      + Σ_j R_Δδ [(Δδf,j / s_Δδf)² + (Δδr,j / s_Δδr)²] + R_ΔMz (ΔMz,j / s_ΔMz)² + ρ ε²

so the effective QP weights are q = (Q_φ/s_φ², Q_Y/s_Y²), r = (R_Δδ/s_Δδf², R_Δδ/s_Δδr²,
R_ΔMz/s_ΔMz²) with s_φ, s_Δδ in rad (:func:`effective_weights`). :func:`equal_effect_scaling`
derives the sizes of ``mpc.yaml`` from the prediction matrices of eq. (6).
"""

from __future__ import annotations

import math

import numpy as np

from fourws_mpc.core.config import MpcConfig
from fourws_mpc.core.model import N_INPUT, N_STATE, InputIdx, StateIdx, discretise
from fourws_mpc.core.qp import augment, output_matrix, prediction_matrices


def effective_weights(cfg: MpcConfig, q_phi: float, q_y: float, r_dd: float, r_dmz: float
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(q_eff (2,), r_eff (3,)) of the QP from paper-scale weights (the module docstring)."""
    s_phi = math.radians(cfg.scale_phi_deg)
    s_df = math.radians(cfg.scale_dsteer_front_deg)
    s_dr = math.radians(cfg.scale_dsteer_rear_deg)
    q = np.array([q_phi / s_phi**2, q_y / cfg.scale_y_m**2])
    r = np.array([r_dd / s_df**2, r_dd / s_dr**2, r_dmz / cfg.scale_dmz_nm**2])
    return q, r


def level_weights(cfg: MpcConfig, r_eff: np.ndarray) -> np.ndarray:
    """s_level (3,) of the input-level penalty (``qp.input_level_cost``): the yaw moment's
    level weighted ``mz_level_weight`` times its increment weight, both on M_z / s_ΔMz, so
    s_Mz = mz_level_weight · r_eff[M_z]; the steering levels are not penalised."""
    s = np.zeros(N_INPUT)
    s[InputIdx.MZ] = cfg.mz_level_weight * r_eff[InputIdx.MZ]
    return s


def equal_effect_scaling(cfg: MpcConfig, speed_mps: float = 60.0 / 3.6
                         ) -> dict[str, float]:
    """The cost scaling's characteristic sizes derived from the prediction model.

    At straight driving at ``speed_mps`` over the baseline horizon N_p (eq. 6): s_Y and s_φ
    are the changes of Y and φ at step N_p after one maximal front-steer increment Δδf,max
    (held), s_Δδr the rear-steer increment with the same lateral effect. Returns
    ``scale_y_m``, ``scale_phi_deg``, ``scale_dsteer_rear_deg`` (docs/mpc.md).
    """
    zeta = np.zeros(N_STATE)
    zeta[StateIdx.VX] = speed_mps
    Ak, Bk, dk = discretise(zeta, np.zeros(N_INPUT), cfg.model_params(), cfg.dt_s)
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
