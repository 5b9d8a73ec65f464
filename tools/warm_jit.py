"""Compile every numba kernel once, so that nodes and runs start from the disk cache.

numba caches a compiled function beside its source (``__pycache__``, ``cache=True``): the
source tree (unit tests) and the colcon install (nodes, ``fourws``) each have their own copy.
``make setup`` runs this once with each on the path; a short closed loop of each kind of
preset (MPC with the terminal cost on both levels and on Y's alone, MPC without it, as the
paper's cost and the fallback when the DARE fails, LQR) reaches every kernel with the types
the runs use. Usage: ``python tools/warm_jit.py``.
"""

from __future__ import annotations

import time

import fourws_common  # noqa: F401 - first: the BLAS thread default
from fourws_bringup.core.closed_loop import run_closed_loop
from fourws_bringup.core.conditions import load_condition

#: (scenario, controller, MPC overrides): every prediction model and cost term the presets use
RUNS = (("dlc_60_mu05", "improved", {}), ("dlc_60_mu05", "mpc_fws", {}),
        ("dlc_60_mu05", "mpc_4ws", {"terminal_cost": "none"}), ("mu_step", "lqr_ff", {}))


def _warm_evidence() -> None:
    """The μ estimate's bisection (``grip._matching_mu``) runs only once the tyres show their
    peak, which the short runs above do not reach: call it on a saturating state."""
    import numpy as np

    from fourws_mpc.core.grip import GripEstimator, GripSettings, peak_slips
    from fourws_mpc.core.model import ModelParams, StateIdx
    from fourws_mpc.core.relaxation_model import N_STATE_RELAX, RelaxIdx

    p = ModelParams()
    zeta = np.zeros(N_STATE_RELAX)
    zeta[StateIdx.VX] = 16.7
    zeta[RelaxIdx.ALPHA_F], zeta[RelaxIdx.ALPHA_R] = peak_slips(p, 0.5)
    if GripEstimator(p, GripSettings()).evidence(zeta, 0.0, 4.0, 0.0, 1.0) is None:
        raise RuntimeError("warm_jit: the saturating state gave no evidence")


def main() -> int:
    t0 = time.perf_counter()
    realistic = load_condition("realistic", 0)
    for scenario, controller, overrides in RUNS:
        run_closed_loop(scenario, controller, max_steps=3, mpc_overrides=overrides)
        run_closed_loop(scenario, controller, max_steps=3, mpc_overrides=overrides,
                        condition=realistic)
    _warm_evidence()
    import fourws_sim

    print(f"[setup] numba kernels ready for {fourws_sim.__file__.rsplit('/', 2)[0]} "
          f"({time.perf_counter() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
