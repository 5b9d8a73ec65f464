"""Per-call cost of the torque-allocation methods and of the speed-PID step.

Usage: python bench/bench_alloc.py [OUT.json]   (default bench/results_alloc.json)

Each method is called ≥ 20 000 times on random but physical inputs (loads 600-3000 N,
μ 0.3-1.0, lateral forces up to 90 % of the grip, |T| ≤ 2000 N·m, |M_z| ≤ 1500 N·m, so
``optimal_bounded`` meets its bounds and priorities often). Each call is timed on its own
with ``time.perf_counter_ns``; the median, p99 and mean are reported in microseconds.
"""

from __future__ import annotations

import json
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for _pkg in ("fourws_common", "fourws_torque_alloc"):
    _p = str(ROOT / "src" / _pkg)
    if _p not in sys.path:
        sys.path.insert(0, _p)

# isort: off
import fourws_common  # noqa: E402, F401 - first: the BLAS thread default
import numpy as np  # noqa: E402
# isort: on

from fourws_torque_alloc.core.allocation import (  # noqa: E402
    AllocatorConfig,
    TorqueAllocator,
)
from fourws_torque_alloc.core.pid import SpeedPid, SpeedPidConfig  # noqa: E402

N_CALLS = 20_000
N_WARMUP = 1_000


def random_inputs(n: int, seed: int = 0) -> list[tuple]:
    rng = np.random.default_rng(seed)
    fz = rng.uniform(600.0, 3000.0, (n, 4))
    mu = rng.uniform(0.3, 1.0, (n, 4))
    fy = rng.uniform(-0.9, 0.9, (n, 4)) * mu * fz
    t = rng.uniform(-2000.0, 2000.0, n)
    mz = rng.uniform(-1500.0, 1500.0, n)
    return [(float(t[i]), float(mz[i]), fz[i], fy[i], mu[i]) for i in range(n)]


def summarise(ns: np.ndarray) -> dict:
    us = ns / 1e3
    return {"calls": int(us.size), "median_us": float(np.median(us)),
            "p99_us": float(np.percentile(us, 99)), "mean_us": float(us.mean()),
            "max_us": float(us.max())}


def bench_allocator(label: str, cfg: AllocatorConfig, inputs: list[tuple]) -> dict:
    alloc = TorqueAllocator(cfg)
    for args in inputs[:N_WARMUP]:
        alloc.allocate(*args)
    ns = np.empty(len(inputs))
    statuses: dict[str, int] = {}
    clock = time.perf_counter_ns
    for k, args in enumerate(inputs):
        t0 = clock()
        res = alloc.allocate(*args)
        ns[k] = clock() - t0
        statuses[res.status] = statuses.get(res.status, 0) + 1
    out = summarise(ns)
    out["statuses"] = statuses
    return out


def bench_pid(n: int) -> dict:
    pid = SpeedPid(SpeedPidConfig())
    rng = np.random.default_rng(1)
    v = (25.0 + rng.normal(0.0, 0.5, n)).tolist()
    for k in range(N_WARMUP):
        pid.step(25.0, v[k], 0.01)
    ns = np.empty(n)
    clock = time.perf_counter_ns
    for k in range(n):
        t0 = clock()
        pid.step(25.0, v[k], 0.01, 0.0)
        ns[k] = clock() - t0
    return summarise(ns)


def main(out_path: str) -> int:
    inputs = random_inputs(N_CALLS)
    results: dict = {
        "machine": {"python": sys.version.split()[0],
                    "cpu": platform.processor() or platform.machine()},
        "calls_per_case": N_CALLS,
        "cases": {},
    }
    cases = {
        "optimal": AllocatorConfig(method="optimal"),
        "optimal_bounded_osqp": AllocatorConfig(method="optimal_bounded", bounded_solver="osqp"),
        "optimal_bounded_analytic": AllocatorConfig(method="optimal_bounded",
                                                    bounded_solver="analytic"),
        "rule": AllocatorConfig(method="rule"),
        "equal": AllocatorConfig(method="equal"),
    }
    for label, cfg in cases.items():
        results["cases"][label] = bench_allocator(label, cfg, inputs)
    results["cases"]["speed_pid_step"] = bench_pid(N_CALLS)

    print(f"{'case':28s} {'median µs':>10s} {'p99 µs':>10s} {'mean µs':>10s} {'max µs':>10s}")
    for label, r in results["cases"].items():
        print(f"{label:28s} {r['median_us']:10.2f} {r['p99_us']:10.2f} {r['mean_us']:10.2f} "
              f"{r['max_us']:10.1f}")
    for label, r in results["cases"].items():
        if "statuses" in r:
            print(f"  {label}: statuses {r['statuses']}")
    Path(out_path).parent.mkdir(parents=True, exist_ok=True)
    Path(out_path).write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    print(f"written {out_path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1] if len(sys.argv) > 1 else
                          str(ROOT / "bench" / "results_alloc.json")))
