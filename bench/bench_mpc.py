"""Benchmark of the full MPC step (errors, weights, horizons, linearisation, build, solve).

Replays a realistic closed-loop trajectory: the ``improved`` controller is run in the
in-process closed loop on dlc_60_mu05 (plant core, PID, allocator) and its per-step plant
outputs are recorded; then, for each forced horizon pair, a fresh ``improved`` controller
(fuzzy weights, DYC) with APCHA switched off and the pair forced as its fixed horizons steps
through the recorded states (≥ 2000 steps, the trajectory repeated with the controller reset
at each lap). Each ``step()`` is timed with ``time.perf_counter`` (wall) and
``time.process_time`` (CPU of this process, insensitive to other load on a shared machine);
median and p99 are printed and written as JSON to argv[1] (default bench/results_mpc.json).
Each pair is run with every QP solver behind the seam (``qp_solver``: OSQP, warm-started,
and DAQP, dense dual active set, cold). Targets, judged on the wall time: p99 ≤ 2 ms at
Np = 30, Nc = 10 (the first target) and p99 ≤ 0.3 ms (issue 20's).

Usage: python bench/bench_mpc.py [out.json] [--steps N]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

from _src_path import ROOT  # noqa: E402, I001 - first: the package sources on sys.path

# isort: off
import fourws_common  # noqa: E402, F401 - first: the BLAS thread default
import numpy as np  # noqa: E402
# isort: on

from fourws_bringup.core.closed_loop import run_closed_loop  # noqa: E402
from fourws_bringup.core.configs import load_mpc_config  # noqa: E402
from fourws_mpc.core.controller import MpcController, VehicleSample  # noqa: E402

PAIRS = ((12, 6), (30, 10))
SOLVERS = ("osqp", "daqp")
SCENARIO = "dlc_60_mu05"
CONTROLLER = "improved"


def record_trajectory() -> tuple[list[VehicleSample], np.ndarray, object]:
    """Per-step measured states and μ (n,) of a closed-loop run."""
    log = run_closed_loop(SCENARIO, CONTROLLER)
    s = log.state
    keys = ("x", "y", "yaw", "vx", "vy", "yaw_rate")
    states = [VehicleSample(*(float(s[k][i]) for k in keys)) for i in range(log.steps)]
    mu = s["mu"].mean(axis=1)
    return states, mu, log.reference


def bench_pair(n_p: int, n_c: int, states: list[VehicleSample], mu: np.ndarray, ref, steps: int,
               solver: str = "osqp") -> dict:
    cfg = load_mpc_config(CONTROLLER, {"horizons_mode": "fixed", "np_baseline": n_p,
                                       "nc_baseline": n_c, "qp_solver": solver})
    ctrl = MpcController(cfg)
    n = len(states)
    times = np.empty(steps)
    cpu = np.empty(steps)
    fallbacks = 0
    iters = np.empty(steps)
    for k in range(steps):
        i = k % n
        if i == 0:
            ctrl.reset()
        c0 = time.process_time()
        t0 = time.perf_counter()
        res = ctrl.step(0.01 * i, states[i], ref, mu=float(mu[i]))
        times[k] = (time.perf_counter() - t0) * 1e3
        cpu[k] = (time.process_time() - c0) * 1e3
        fallbacks += res.fallback
        iters[k] = res.iterations
    return {
        "np": n_p, "nc": n_c, "solver": solver, "steps": steps,
        "median_ms": float(np.median(times)), "p99_ms": float(np.percentile(times, 99)),
        "max_ms": float(times.max()), "mean_ms": float(times.mean()),
        "cpu_median_ms": float(np.median(cpu)), "cpu_p99_ms": float(np.percentile(cpu, 99)),
        "fallbacks": int(fallbacks), "solver_iterations_median": float(np.median(iters)),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(ROOT / "bench" / "results_mpc.json"))
    ap.add_argument("--steps", type=int, default=3000)
    args = ap.parse_args()
    if args.steps < 2000:
        ap.error("--steps must be at least 2000")
    states, mu, ref = record_trajectory()
    results = {
        "benchmark": "mpc_step", "scenario": SCENARIO, "controller": CONTROLLER,
        "trajectory_steps": int(len(states)), "python": platform.python_version(),
        "machine": platform.machine(), "pairs": [],
    }
    for solver in SOLVERS:
        for n_p, n_c in PAIRS:
            r = bench_pair(n_p, n_c, states, mu, ref, args.steps, solver)
            results["pairs"].append(r)
            print(f"MPC step {solver} Np={n_p:2d} Nc={n_c:2d}: wall median "
                  f"{r['median_ms']:.3f} ms, p99 {r['p99_ms']:.3f} ms, max {r['max_ms']:.3f} "
                  f"ms; CPU median {r['cpu_median_ms']:.3f} ms, p99 {r['cpu_p99_ms']:.3f} ms "
                  f"over {r['steps']} steps (fallbacks {r['fallbacks']}, solver iterations "
                  f"median {r['solver_iterations_median']:.0f})")
    results["target_p99_ms_at_30_10"] = 2.0
    results["target_p99_ms_at_30_10_issue20"] = 0.3
    for solver in SOLVERS:
        p30 = next(r for r in results["pairs"]
                   if (r["np"], r["nc"], r["solver"]) == (30, 10, solver))
        results[f"meets_target_{solver}"] = bool(p30["p99_ms"] <= 2.0)
        results[f"meets_target_issue20_{solver}"] = bool(p30["p99_ms"] <= 0.3)
    results["meets_target"] = results["meets_target_osqp"]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
