"""Sweep throughput: runs per minute of ``fourws sweep`` on this machine's cores.

Usage: python bench/bench_sweep.py [OUT.json] [--jobs N] [--workers W]
       (default bench/results_sweep.json, 12 jobs, one worker per core)

Runs ``N`` jobs of ``benchmarks/robustness.yaml`` (every ⌊546/N⌋-th job in spec order, so the
sample spans its controllers, scenarios and conditions) through the sweep's own runner
(:func:`fourws_bringup.sweep.run_sweep`, ``W`` worker processes) and times the whole batch:
runs per minute, and the minutes the whole robustness benchmark would take at that rate
(issue 20's target: ≤ 10 min on 2 cores). A projection from a sample, stated as one; the
summary's margins and the report writing are not included.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

from _src_path import ROOT  # noqa: E402, I001 - first: the package sources on sys.path

import fourws_common  # noqa: E402, F401 - first: the BLAS thread default

SPEC = ROOT / "benchmarks" / "robustness.yaml"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(ROOT / "bench" / "results_sweep.json"))
    ap.add_argument("--jobs", type=int, default=12)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    args = ap.parse_args()
    from fourws_bringup.sweep import load_spec, run_sweep

    cwd = os.getcwd()
    os.chdir(SPEC.parent)  # the spec's scenario paths are relative to it
    try:
        jobs = load_spec(SPEC)
        step = max(1, len(jobs) // args.jobs)
        sample = jobs[::step][:args.jobs]
        t0 = time.perf_counter()
        rows = run_sweep(sample, workers=args.workers, progress=False)
        wall = time.perf_counter() - t0
    finally:
        os.chdir(cwd)
    per_min = len(sample) / wall * 60.0
    res = {"benchmark": "sweep_throughput", "spec": "benchmarks/robustness.yaml",
           "spec_jobs": len(jobs), "sample_jobs": len(sample), "workers": args.workers,
           "wall_s": wall, "runs_per_minute": per_min,
           "completed": int(sum(bool(r.get("completed")) for r in rows)),
           "projected_spec_minutes": len(jobs) / per_min, "target_minutes": 10.0}
    res["meets_target"] = bool(res["projected_spec_minutes"] <= 10.0)
    print(f"sweep: {len(sample)} runs of {SPEC.name} in {wall:.1f} s with {args.workers} "
          f"workers: {per_min:.1f} runs/min; the whole spec ({len(jobs)} runs) projected at "
          f"{res['projected_spec_minutes']:.1f} min (target 10)")
    Path(args.out).write_text(json.dumps(res, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
