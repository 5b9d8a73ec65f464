"""Whether the MPC step's tail is the data's or the machine's (docs/mpc.md, "Benchmark").

Usage: python bench/mpc_tail.py [N_P N_C] [--laps L]   (default 12 6, 5 laps)

Replays ``bench_mpc.py``'s recorded states through one improved controller (DAQP, horizons
forced) ``L`` times, the first lap a warm-up, and times each step. Prints the steps' median
and p99, the p99 of the per-state median over the laps, the correlation of the step times
between two laps (near 0: a slow step does not repeat at the same state), and the same with
Python's garbage collector off. Not part of ``make bench``: a diagnosis, not a figure.
"""

from __future__ import annotations

import argparse
import gc
import time

import _src_path  # noqa: F401 - the checkout's sources first
import numpy as np


def laps(n_p: int, n_c: int, n_laps: int, states, mu, ref) -> np.ndarray:
    """Step times (ms), shape (n_laps − 1, n_states), the warm-up lap dropped."""
    from fourws_bringup.core.configs import load_mpc_config
    from fourws_mpc.core.controller import MpcController

    cfg = load_mpc_config("improved", {"horizons_mode": "fixed", "np_baseline": n_p,
                                       "nc_baseline": n_c, "qp_solver": "daqp"})
    ctrl = MpcController(cfg)
    t = np.empty((n_laps, len(states)))
    for lap in range(n_laps):
        ctrl.reset()
        for i, s in enumerate(states):
            t0 = time.perf_counter()
            ctrl.step(0.01 * i, s, ref, mu=float(mu[i]))
            t[lap, i] = (time.perf_counter() - t0) * 1e3
    return t[1:]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pair", nargs="*", type=int, default=[12, 6])
    ap.add_argument("--laps", type=int, default=5)
    args = ap.parse_args()
    if len(args.pair) != 2 or args.laps < 3:
        ap.error("give N_P N_C and at least 3 laps")
    from bench_mpc import record_trajectory

    states, mu, ref = record_trajectory()
    for label, collect in (("gc on", True), ("gc off", False)):
        if not collect:
            gc.disable()
        t = laps(*args.pair, args.laps, states, mu, ref)
        gc.enable()
        per_state = np.median(t, axis=0)
        print(f"{label}: steps median {np.median(t):.3f} ms, p99 {np.percentile(t, 99):.3f} "
              f"ms; per-state median p99 {np.percentile(per_state, 99):.3f} ms; lap-to-lap "
              f"correlation {np.corrcoef(t[0], t[1])[0, 1]:+.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
