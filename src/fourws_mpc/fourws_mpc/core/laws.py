"""Picks the lateral control law by name (parameter ``law``), behind one interface.

The MPC of section 3 and the textbook reference ``lqr_ff`` share ``step``, ``reset``,
``update_config``, ``adopt_reference`` and ``u_prev`` (docs/architecture.md, "Seams")."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from fourws_common.params import choose
from fourws_mpc.core.config import MpcConfig
from fourws_mpc.core.controller import MpcController, VehicleSample
from fourws_mpc.core.lqr_controller import LqrFfController

LAWS: dict[str, Callable[[MpcConfig], MpcController | LqrFfController]] = {
    "mpc": MpcController, "lqr_ff": LqrFfController}


def make_controller(cfg: MpcConfig) -> MpcController | LqrFfController:
    """The controller of ``cfg.law``."""
    return choose(LAWS, cfg.law, "law")(cfg)


def warm_up(cfg: MpcConfig) -> None:
    """One step of a throwaway controller of ``cfg`` on a straight road: it loads the
    compiled kernels from numba's disk cache (docs/architecture.md, "Compiled numerics"), so
    that a node's first real step stays within the control period. Nothing is kept."""
    n = 100
    x = np.linspace(0.0, 99.0, n)
    zeros = np.zeros(n)
    ref = cfg.reference(x, zeros, zeros, zeros, np.full(n, 10.0))
    make_controller(cfg).step(0.0, VehicleSample(0.0, 0.01, 0.0, 10.0, 0.0, 0.0), ref, mu=0.8)
