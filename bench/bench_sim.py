"""Benchmark of the plant core: wall time of one 10 ms step (10 RK4 substeps of 1 ms).

Usage: python bench/bench_sim.py [OUT_JSON]   (default bench/results_sim.json)

Drives the dlc_60_mu05 scenario's simulator with a scripted steer/torque sequence and times
every ``Simulator.step`` (outputs included) with ``time.perf_counter``. Also reports, for the
trade-off: the step without building the outputs, the step with a 2 ms substep, a μ-step road
(per-substep μ lookup), and one four-wheel tyre evaluation in plain floats vs numpy. The four
step variants take turns step by step, so their ratios hold when the host changes speed.
Writes {median_ms, p99_ms, ...} as JSON and prints it.
"""

from __future__ import annotations

import json
import math
import platform
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for pkg in ("fourws_common", "fourws_sim"):
    sys.path.insert(0, str(ROOT / "src" / pkg))


# isort: off
import fourws_common  # noqa: E402, F401 - first: the BLAS thread default
import numpy as np  # noqa: E402
# isort: on

from fourws_sim.core import tyre  # noqa: E402
from fourws_sim.core.scenario import load_scenario  # noqa: E402
from fourws_sim.core.simulator import Simulator  # noqa: E402

N_STEPS = 3000
WARMUP = 200


def _commands(k: int) -> tuple[float, float, np.ndarray]:
    t = 0.01 * k
    d = math.radians(1.5) * math.sin(2 * math.pi * t / 3.0)
    return d, -0.3 * d, np.array([60.0, 80.0, 60.0, 80.0]) + 10.0 * math.sin(t)


def _time_steps(*cases: tuple[Simulator, str], n: int = N_STEPS) -> list[list[float]]:
    """Wall time (ms) of each step of every (simulator, method) case. The cases take turns
    step by step, so a change in the host's speed during the bench hits them alike."""
    fns = [getattr(sim, method) for sim, method in cases]
    for k in range(WARMUP):
        for fn in fns:
            fn(*_commands(k))
    times: list[list[float]] = [[] for _ in fns]
    for k in range(n):
        cmd = _commands(WARMUP + k)
        for fn, out in zip(fns, times, strict=True):
            t0 = time.perf_counter()
            fn(*cmd)
            out.append((time.perf_counter() - t0) * 1e3)
    return times


def _p99(times: list[float]) -> float:
    return float(np.percentile(times, 99))


def _tyre_evals(n: int = 20000) -> tuple[float, float]:
    p = load_scenario("dlc_60_mu05").vehicle
    front = p.tyre("front")
    k = front.scalar_constants(front.cornering_coeff)
    all4 = p.tyre("all")
    kap = np.array([0.01, 0.012, 0.009, 0.011])
    alp = np.array([0.02, 0.025, 0.018, 0.022])
    fz = np.array([1800.0, 2100.0, 1600.0, 1900.0])
    mu = np.full(4, 0.5)
    t0 = time.perf_counter()
    for _ in range(n):
        for _wheel in range(4):
            tyre.forces_scalar(0.01, 0.02, 1800.0, 0.5, k)
    t_scalar = (time.perf_counter() - t0) / n * 1e6
    t0 = time.perf_counter()
    for _ in range(n // 10):
        tyre.forces(kap, alp, fz, mu, all4)
    t_numpy = (time.perf_counter() - t0) / (n // 10) * 1e6
    return t_scalar, t_numpy


def main() -> None:
    out_path = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "bench" / "results_sim.json"
    scenario = load_scenario("dlc_60_mu05")
    mu_step = load_scenario("mu_step")
    step, advance, coarse, piecewise = _time_steps(
        (Simulator.from_scenario(scenario), "step"),
        (Simulator.from_scenario(scenario), "advance"),
        (Simulator.from_scenario(scenario, substep_s=0.002), "step"),
        (Simulator.from_scenario(mu_step), "step"))
    t_scalar, t_numpy = _tyre_evals()
    result = {
        "median_ms": round(statistics.median(step), 4),
        "p99_ms": round(_p99(step), 4),
        "what": "Simulator.step(dt_s=0.01), substep 1 ms RK4 (40 derivative evaluations), "
                "outputs included; scenario dlc_60_mu05",
        "steps": N_STEPS,
        "target_ms": 0.03,
        "without_outputs_median_ms": round(statistics.median(advance), 4),
        "substep_2ms_median_ms": round(statistics.median(coarse), 4),
        "piecewise_mu_road_median_ms": round(statistics.median(piecewise), 4),
        "tyre_4_wheels_plain_float_us": round(t_scalar, 3),
        "tyre_4_wheels_numpy_us": round(t_numpy, 3),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "machine": platform.machine(),
    }
    out_path.parent.mkdir(parents=True, exist_ok=True)
    out_path.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
