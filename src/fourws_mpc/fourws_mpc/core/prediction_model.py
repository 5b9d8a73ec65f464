"""The model seam: what the MPC needs of its prediction model, and the paper's model behind it.

A prediction model turns an operating point into the affine discrete model of eq. (4)::

    ζ(k+1) = A_k ζ(k) + B_k u(k) + d_k

(:meth:`PredictionModel.discretise`); the QP condenses it over the horizon (``qp``). Models
are chosen by name (:data:`PREDICTION_MODELS`, parameter ``prediction_model``) or injected
into :class:`~fourws_mpc.core.controller.MpcController` directly.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from fourws_common.params import choose
from fourws_mpc.core.model import ModelParams, discretise


class PredictionModel(Protocol):
    """Discretise the model at a state and input."""

    def discretise(self, zeta: np.ndarray, u: np.ndarray, dt_s: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A_k, B_k, d_k) of eq. (4) at (ζ, u) for the period ``dt_s``."""


class SingleTrackModel:
    """The paper's 3-DOF single-track model, eq. (1)-(4), linearised exactly at (ζ0, u0)
    (``model.discretise``)."""

    name = "single_track"

    def __init__(self, params: ModelParams) -> None:
        self.params = params

    def discretise(self, zeta: np.ndarray, u: np.ndarray, dt_s: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A_k, B_k, d_k) of eq. (4)."""
        return discretise(zeta, u, self.params, dt_s)


#: model name (parameter ``prediction_model``) -> factory from the model parameters
PREDICTION_MODELS: dict[str, Callable[[ModelParams], PredictionModel]] = {
    "single_track": SingleTrackModel,
}


def make_prediction_model(name: str, params: ModelParams) -> PredictionModel:
    """The model called ``name`` (:data:`PREDICTION_MODELS`)."""
    return choose(PREDICTION_MODELS, name, "prediction_model")(params)
