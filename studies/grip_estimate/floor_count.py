#!/usr/bin/env python3
"""How often the MPC's μ estimate reaches its floor under the realistic condition.

    python studies/grip_estimate/floor_count.py [--controller improved] [--workers 2]

Runs the controller in the in-process loop (``run_closed_loop``) under the shipped realistic
condition, seeds 0-4, on every scenario of the limit bench but split-μ braking and on the
robustness bench's four scenarios, and counts the runs in which ``mu_estimate`` touches the
preset's ``mu_floor``: the estimator's own floor, reached only by evidence
(``fourws_mpc/core/grip.py``). Prints, per such run, the steps at the floor, the plant's true
|a_y| at most while there and whether the run completed (studies/grip_estimate/README.md).
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from fourws_bringup.core.closed_loop import run_closed_loop
from fourws_bringup.core.conditions import load_condition
from fourws_bringup.core.configs import load_mpc_config

ROOT = Path(__file__).resolve().parents[2]
BENCH = ("bench_dlc_60_mu05", "bench_dlc_90_mu06", "bench_iso3888_60_mu08",
         "bench_iso3888_80_mu08")


def _one(job: tuple[str, str, int]) -> tuple[str, int, int, float, bool]:
    scenario, controller, seed = job
    condition = load_condition("realistic", seed)
    floor = load_mpc_config(controller).mu_floor
    log = run_closed_loop(scenario, controller, condition=condition)
    at_floor = np.asarray(log.mpc["mu_estimate"], dtype=float) <= floor * (1.0 + 1e-9)
    ay_true = np.abs(np.asarray(log.state["ay"], dtype=float))   # the log's state: the truth
    return (Path(scenario).stem, seed, int(at_floor.sum()),
            float(ay_true[at_floor].max()) if at_floor.any() else 0.0, bool(log.completed))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--controller", default="improved")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    limits = sorted(str(p) for p in (ROOT / "benchmarks" / "limits").glob("*.yaml")
                    if "braking" not in p.name)
    bench = [str(ROOT / "benchmarks" / "scenarios" / f"{s}.yaml") for s in BENCH]
    jobs = [(s, args.controller, seed) for s in limits + bench for seed in range(5)]
    with ProcessPoolExecutor(max(1, args.workers)) as ex:
        rows = list(ex.map(_one, jobs))
    hit = [r for r in rows if r[2] > 0]
    print(f"{args.controller}: mu_estimate at its floor in {len(hit)} of {len(rows)} runs")
    print("| scenario | seed | steps at the floor | max true abs a_y there (m/s²) | completed |")
    print("|---|---|---|---|---|")
    for name, seed, steps, ay, done in hit:
        print(f"| {name} | {seed} | {steps} | {ay:.2f} | {done} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
