"""Compile every numba kernel once, so that nodes and runs start from the disk cache.

numba caches a compiled function beside its source (``__pycache__``, ``cache=True``): the
source tree (unit tests) and the colcon install (nodes, ``fourws``) each have their own copy.
``make setup`` runs this once with each on the path; a short closed loop of each kind of
preset (MPC with the terminal cost on both levels and on Y's alone, MPC without it, as the
paper's cost and the fallback when the DARE fails, LQR) reaches every kernel with the types
the runs use. numba checks only a kernel's own file for staleness, so when any kernel source
(every ``core/`` and ``fourws_common``) changed since the last warm-up every cached kernel is
deleted first (:func:`drop_stale_caches`). Usage: ``python tools/warm_jit.py``.
"""

from __future__ import annotations

import hashlib
import importlib
import time
from pathlib import Path

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


#: the packages whose kernels call each other (a kernel may inline another file's function)
PACKAGES = ("fourws_common", "fourws_sim", "fourws_mpc", "fourws_torque_alloc", "fourws_bringup")
#: where the sources' fingerprint of the last warm-up is kept, beside the caches it vouches for
STAMP = "__pycache__/fourws_kernel_sources.sha256"


def kernel_sources(d: Path) -> list[Path]:
    """The files of package folder ``d`` that kernels are compiled from: its ``core/``, and
    the whole of ``fourws_common`` (``load_transfer`` is compiled by its users)."""
    return sorted(d.rglob("*.py") if d.name == "fourws_common" else (d / "core").glob("*.py"))


def drop_stale_caches() -> int:
    """numba checks only a kernel's own file for staleness, not the files of the functions
    it calls (``qp._build`` calls ``condense``; docs/architecture.md, "Compiled numerics").
    If any kernel source of the packages on the path changed since the last warm-up, delete
    every cached kernel of theirs so that all compile afresh; returns how many files went."""
    dirs = [Path(importlib.import_module(name).__file__).parent for name in PACKAGES]
    digest = hashlib.sha256()
    for d in dirs:
        for f in kernel_sources(d):
            digest.update(str(f.relative_to(d.parent)).encode() + b"\0" + f.read_bytes())
    stamp = dirs[0] / STAMP
    if stamp.is_file() and stamp.read_text(encoding="utf-8") == digest.hexdigest():
        return 0
    gone = 0
    for d in dirs:
        for f in [*d.rglob("*.nbi"), *d.rglob("*.nbc")]:
            f.unlink(missing_ok=True)
            gone += 1
    stamp.parent.mkdir(exist_ok=True)
    stamp.write_text(digest.hexdigest(), encoding="utf-8")
    return gone


def main() -> int:
    t0 = time.perf_counter()
    dropped = drop_stale_caches()
    realistic = load_condition("realistic", 0)
    for scenario, controller, overrides in RUNS:
        run_closed_loop(scenario, controller, max_steps=3, mpc_overrides=overrides)
        run_closed_loop(scenario, controller, max_steps=3, mpc_overrides=overrides,
                        condition=realistic)
    _warm_evidence()
    import fourws_sim

    print(f"[setup] numba kernels ready for {fourws_sim.__file__.rsplit('/', 2)[0]} "
          f"({time.perf_counter() - t0:.1f} s"
          f"{f'; sources changed: {dropped} cached files recompiled' if dropped else ''})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
