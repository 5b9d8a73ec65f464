"""Defines the model seam: what the MPC needs of its prediction model, and the models behind it.

A prediction model turns an operating point into the affine discrete model of eq. (4)::

    ζ(k+1) = A_k ζ(k) + B_k u(k) + d_k

(:meth:`PredictionModel.discretise`); the QP condenses it over the horizon (``qp``). Models
are chosen by name (:data:`PREDICTION_MODELS`, parameter ``prediction_model``) or injected
into :class:`~fourws_mpc.core.controller.MpcController` directly
(docs/architecture.md, "Seams"). A model's state may extend ζ of eq. (1) by states appended
after ``StateIdx.X`` (``n_state``; :meth:`measured_state` builds it from the measured ζ and
the measured road-wheel angles, and estimates what is not measured from a memory the caller
carries from step to step and commits).

Discretisation of the linearisation ζ̇ ≈ A_t ζ + B_t u + c, c = f(ζ0, u0) − A_t ζ0 − B_t u0
(parameter ``prediction_discretisation``):

* ``euler`` (the paper's eq. (4)): A_k = I + T A_t, B_k = T B_t, d_k = T c;
* ``zoh`` (exact for the linearised model with the input held over the period)::

      expm(T [[A_t, B_t, c], [0, 0, 0]]) = [[A_k, B_k, d_k], [0, I, 0]]

  With a 20 ms steering lag and T = 10 ms forward Euler maps the lag's pole e^{−T/τ} = 0.61
  to 1 − T/τ = 0.5; the zero-order hold is exact (docs/mpc.md, "Actuator-aware prediction").
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from fourws_common.params import choose
from fourws_mpc.core import actuator_model, friction_model, relaxation_model
from fourws_mpc.core.model import (
    N_STATE,
    ModelParams,
    affine_euler,
    affine_zoh,
    as_vector,
    jacobians,
    packed,
)

__all__ = ["affine_euler", "affine_zoh"]  # the discretisations live in model.py

DISCRETISATIONS = ("euler", "zoh")


class PredictionModel(Protocol):
    """Discretise the model at a state and input."""

    n_state: int

    def discretise(self, zeta: np.ndarray, u: np.ndarray, dt_s: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A_k, B_k, d_k) of eq. (4) at (ζ, u) for the period ``dt_s``."""

    def measured_state(self, zeta: np.ndarray, steer_front: float, steer_rear: float,
                       memory: Any = None, dt_s: float = 0.0) -> tuple[np.ndarray, Any]:
        """The model's state from ζ of eq. (1) (6,) and the actual road-wheel angles, and
        the memory for the next step (``None`` for a model that estimates nothing).
        ``memory`` is what the previous step returned (``None``: start afresh), ``dt_s``
        the time since it."""


def _discretiser(name: str) -> Callable:
    if name not in DISCRETISATIONS:
        raise ValueError(f"prediction_discretisation: '{name}' is not one of "
                         f"{list(DISCRETISATIONS)}")
    return affine_euler if name == "euler" else affine_zoh


class _Discretised:
    """What both models share: their parameters and the chosen discretisation."""

    def __init__(self, params: ModelParams, discretisation: str = "euler") -> None:
        self.params = params
        self.discretisation = discretisation
        self._disc = _discretiser(discretisation)


class SingleTrackModel(_Discretised):
    """The paper's 3-DOF single-track model, eq. (1)-(4), linearised exactly at (ζ0, u0)
    (``model.discretise``; with ``zoh``, the hold-equivalent of the same linearisation)."""

    name = "single_track"
    n_state = N_STATE

    def discretise(self, zeta: np.ndarray, u: np.ndarray, dt_s: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A_k, B_k, d_k) of eq. (4)."""
        return self._disc(*jacobians(zeta, u, self.params), zeta, u, dt_s)

    def measured_state(self, zeta: np.ndarray, steer_front: float, steer_rear: float,
                       memory: Any = None, dt_s: float = 0.0) -> tuple[np.ndarray, Any]:
        """ζ itself: eq. (1) takes the commanded angles."""
        return zeta, None


class SingleTrackActuatorModel(_Discretised):
    """Eq. (1) with the steering actuators' first-order lag (``actuator_model``): state
    [ζ; δf,act; δr,act], linearised exactly at (ζ0, u0)."""

    name = "single_track_actuators"
    n_state = actuator_model.N_STATE_ACT

    def discretise(self, zeta: np.ndarray, u: np.ndarray, dt_s: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A_k, B_k, d_k) of the extended model, (8, 8), (8, 3), (8,)."""
        return self._disc(*actuator_model.jacobians(zeta, u, self.params), zeta, u, dt_s)

    def measured_state(self, zeta: np.ndarray, steer_front: float, steer_rear: float,
                       memory: Any = None, dt_s: float = 0.0) -> tuple[np.ndarray, Any]:
        """[ζ; δf,act; δr,act] with the measured road-wheel angles."""
        return np.concatenate([zeta[:N_STATE], [steer_front, steer_rear]]), None


class SingleTrackRelaxationModel(_Discretised):
    """Eq. (1) with the steering lags and the tyres' lateral relaxation
    (``relaxation_model``): state [ζ; δf,act; δr,act; α'f; α'r], α' estimated by the
    :class:`~fourws_mpc.core.relaxation_model.SlipObserver` from the measured kinematic slip."""

    name = "single_track_relaxation"
    n_state = relaxation_model.N_STATE_RELAX

    def __init__(self, params: ModelParams, discretisation: str = "euler") -> None:
        super().__init__(params, discretisation)
        self.observer = relaxation_model.SlipObserver(params)   # checks σ > 0
        self._packed = packed(params)      # once: the kernels' form of the parameters

    def discretise(self, zeta: np.ndarray, u: np.ndarray, dt_s: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A_k, B_k, d_k) of the extended model, (10, 10), (10, 3), (10,)."""
        zeta, u = as_vector(zeta), as_vector(u)
        return self._disc(*relaxation_model.jacobians_compiled(zeta, u, self._packed), zeta, u,
                          dt_s)

    def measured_state(self, zeta: np.ndarray, steer_front: float, steer_rear: float,
                       memory: Any = None, dt_s: float = 0.0) -> tuple[np.ndarray, Any]:
        """[ζ; δf,act; δr,act; α̂'f; α̂'r]: the measured road-wheel angles and the
        observer's estimate (its memory is returned for the next step)."""
        z = np.zeros(relaxation_model.N_STATE_RELAX)
        z[:N_STATE] = zeta[:N_STATE]
        z[actuator_model.ActIdx.DF_ACT], z[actuator_model.ActIdx.DR_ACT] = steer_front, steer_rear
        alpha, memory = self.observer.estimate(z, memory, dt_s)
        z[relaxation_model.RelaxIdx.ALPHA_F], z[relaxation_model.RelaxIdx.ALPHA_R] = alpha
        return z, memory


class SingleTrackFrictionModel(SingleTrackRelaxationModel):
    """The relaxation model with saturating axle forces whose peaks follow the road and the
    friction ellipse (``friction_model``). The road is :attr:`grip`, which the controller
    sets from its μ estimate and the measured a_x, a_y before each :meth:`discretise`."""

    name = "single_track_friction"
    grip_aware = True

    def __init__(self, params: ModelParams, discretisation: str = "euler") -> None:
        super().__init__(params, discretisation)
        self.grip = friction_model.Grip()

    def discretise(self, zeta: np.ndarray, u: np.ndarray, dt_s: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A_k, B_k, d_k) of the friction-aware model at :attr:`grip`, (10, 10), (10, 3),
        (10,)."""
        zeta, u = as_vector(zeta), as_vector(u)
        g = self.grip
        return self._disc(*friction_model.jacobians_compiled(
            zeta, u, self._packed, float(g.mu), float(g.ax_mps2), float(g.ay_mps2)), zeta, u,
            dt_s)


#: the models whose state holds the transient slips α' (``relaxation_model.RelaxIdx``)
RELAXATION_MODELS = ("single_track_relaxation", "single_track_friction")

#: model name (parameter ``prediction_model``) -> factory from the model parameters and the
#: discretisation (parameter ``prediction_discretisation``)
PREDICTION_MODELS: dict[str, Callable[..., PredictionModel]] = {
    "single_track": SingleTrackModel,
    "single_track_actuators": SingleTrackActuatorModel,
    "single_track_relaxation": SingleTrackRelaxationModel,
    "single_track_friction": SingleTrackFrictionModel,
}


def make_prediction_model(name: str, params: ModelParams, discretisation: str = "euler"
                          ) -> PredictionModel:
    """The model called ``name`` (:data:`PREDICTION_MODELS`)."""
    return choose(PREDICTION_MODELS, name, "prediction_model")(params, discretisation)
