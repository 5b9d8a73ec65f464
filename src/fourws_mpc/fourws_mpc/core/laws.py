"""The lateral control laws by name (parameter ``law``): the MPC of section 3 and the
textbook reference ``lqr_ff``, behind one interface (``step``, ``reset``,
``update_config``, ``adopt_reference``, ``u_prev``)."""

from __future__ import annotations

from collections.abc import Callable

from fourws_common.params import choose
from fourws_mpc.core.config import MpcConfig
from fourws_mpc.core.controller import MpcController
from fourws_mpc.core.lqr_controller import LqrFfController

LAWS: dict[str, Callable[[MpcConfig], MpcController | LqrFfController]] = {
    "mpc": MpcController, "lqr_ff": LqrFfController}


def make_controller(cfg: MpcConfig) -> MpcController | LqrFfController:
    """The controller of ``cfg.law``."""
    return choose(LAWS, cfg.law, "law")(cfg)
