"""Benchmark of the QP solvers alone, on the QPs the MPC actually solves.

Usage: python bench/bench_qp.py [OUT.json]   (default bench/results_qp.json)

The ``improved`` controller with fixed horizons (Np, Nc) = (12, 6) and (30, 10) is run in the
in-process closed loop on dlc_60_mu05 with OSQP behind the solver seam; a recording solver
keeps a copy of every condensed QP it is handed. Each captured sequence is then solved again,
in order, by every solver of ``qp_solver.QP_SOLVERS`` (OSQP warm-started from its previous
solution as in the loop, DAQP cold), and each ``solve`` (data check and update included) is
timed with ``time.perf_counter``: median and p99 per solver and pair. The solutions are
compared in units of the increment bound (the QP's variables are Δu/Δu_max): the largest
difference from DAQP's exact active-set solution, per solver.
"""

from __future__ import annotations

import copy
import json
import sys
import time
from pathlib import Path

import _src_path  # noqa: E402, F401, I001 - first: the package sources on sys.path

# isort: off
import fourws_common  # noqa: E402, F401 - first: the BLAS thread default
import numpy as np  # noqa: E402
# isort: on

from fourws_bringup.core.closed_loop import run_closed_loop  # noqa: E402
from fourws_mpc.core.qp_solver import QP_SOLVERS, QpSettings  # noqa: E402

PAIRS = ((12, 6), (30, 10))
SCENARIO = "dlc_60_mu05"
CONTROLLER = "improved"


class Recorder:
    """OSQP behind the seam, keeping a copy of every QP it solves."""

    name = "recorder"

    def __init__(self) -> None:
        self.inner = QP_SOLVERS["osqp"](QpSettings())
        self.qps: list = []

    def prepare(self, pattern) -> None:
        self.inner.prepare(pattern)

    def reset(self) -> None:
        self.inner.reset()

    def solve(self, qp, warm_x):
        self.qps.append((copy.deepcopy(qp), None if warm_x is None else warm_x.copy()))
        return self.inner.solve(qp, warm_x)


def capture(n_p: int, n_c: int) -> list:
    rec = Recorder()
    import fourws_bringup.core.closed_loop as cl
    from fourws_mpc.core.controller import MpcController

    original = cl.make_controller
    cl.make_controller = lambda cfg: MpcController(cfg, solver=rec)
    try:
        run_closed_loop(SCENARIO, CONTROLLER, mpc_overrides={
            "horizons_mode": "fixed", "np_baseline": n_p, "nc_baseline": n_c})
    finally:
        cl.make_controller = original
    return rec.qps


def time_solver(name: str, qps: list) -> tuple[np.ndarray, list]:
    solver = QP_SOLVERS[name](QpSettings())
    times, xs = np.empty(len(qps)), []
    for i, (qp, warm) in enumerate(qps):
        solver.prepare(qp.pattern)
        t0 = time.perf_counter()
        res = solver.solve(qp, warm)
        times[i] = (time.perf_counter() - t0) * 1e3
        xs.append(res.x)
    return times, xs


def main(out: str) -> int:
    results = {"benchmark": "qp_solvers_on_captured_qps", "scenario": SCENARIO,
               "controller": CONTROLLER, "pairs": []}
    for n_p, n_c in PAIRS:
        qps = capture(n_p, n_c)
        solved = {name: time_solver(name, qps) for name in QP_SOLVERS}
        ref = solved["daqp"][1]
        for name, (times, xs) in solved.items():
            diffs = [float(np.max(np.abs(x[:-1] - r[:-1]))) for x, r in zip(xs, ref, strict=True)
                     if x is not None and r is not None]
            row = {"np": n_p, "nc": n_c, "solver": name, "qps": len(qps),
                   "median_ms": float(np.median(times)),
                   "p99_ms": float(np.percentile(times, 99)),
                   "failed": int(sum(x is None for x in xs)),
                   "max_diff_from_daqp_du_bounds": max(diffs) if diffs else None}
            results["pairs"].append(row)
            print(f"QP alone {name:4s} Np={n_p:2d} Nc={n_c:2d}: median {row['median_ms']:.3f} ms,"
                  f" p99 {row['p99_ms']:.3f} ms over {len(qps)} captured QPs (failed "
                  f"{row['failed']}; largest |Δz - Δz_daqp| "
                  f"{row['max_diff_from_daqp_du_bounds']:.1e} of the increment bound)")
    Path(out).write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1] if len(sys.argv) > 1 else "bench/results_qp.json"))
