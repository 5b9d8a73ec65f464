#!/usr/bin/env python3
"""How much of a noisy run's max |eY| is the localisation error itself, per seed.

    python tools/noise_floor.py runs/lqr-comparison/results.csv [--condition all]
        [--noise realistic] [--channel y] [--dt 0.01]

Every seed of a sweep draws its measurement noise from its own generator
(``fourws_sim.core.sensing``: one stream per (seed, channel), one sample per step), so the
error the controllers were given on ``channel`` can be drawn again here without the run. Its
largest magnitude over a run's steps is the *floor*: a controller that holds the measured
position exactly has a true max |eY| equal to it (the paths stay within a few degrees of the
x axis, so the y channel is the lateral one). Per scenario and controller: the median max
|eY|, the median floor, the median ratio of the two and their correlation over seeds (near 1:
the run's max is the localisation error; low: the controller filters the noise and adds an
error of its own). Markdown on stdout, in mm.
"""

from __future__ import annotations

import argparse
import csv
import statistics
import sys
from collections import defaultdict
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from fourws_bringup.core.conditions import load_condition
from fourws_sim.core.sensing import MeasurementNoise, NoiseSpec


def floor_m(noise: Mapping[str, NoiseSpec], seed: int, steps: int, dt_s: float,
            channel: str = "y") -> float:
    """Largest |error| of ``channel`` over ``steps`` draws of the run of ``seed``."""
    stream = MeasurementNoise(dict(noise), dt_s, seed)
    return float(max((abs(stream.errors().get(channel, 0.0)) for _ in range(steps)),
                     default=0.0))


def analyse(path: Path, noise: Mapping[str, NoiseSpec], dt_s: float, channel: str,
            condition: str | None) -> list[dict]:
    runs: dict[tuple[str, str], dict[int, tuple[float, int]]] = defaultdict(dict)
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            if condition is not None and r["condition"] != condition:
                continue
            if r.get("completed", "True") != "True":
                continue
            runs[(Path(r["scenario"]).stem, r["controller"])][int(r["seed"])] = (
                float(r["max_abs_lateral_error_m"]), int(r["steps"]))
    cache: dict[tuple[int, int], float] = {}
    table = []
    for (scenario, controller), by_seed in sorted(runs.items()):
        seeds = sorted(by_seed)
        got = np.array([by_seed[s][0] for s in seeds])
        floors = []
        for s in seeds:
            key = (s, by_seed[s][1])
            if key not in cache:
                cache[key] = floor_m(noise, s, by_seed[s][1], dt_s, channel)
            floors.append(cache[key])
        floors = np.array(floors)
        corr = (float(np.corrcoef(floors, got)[0, 1])
                if len(seeds) >= 3 and got.std() > 0.0 and floors.std() > 0.0 else None)
        table.append({"scenario": scenario, "controller": controller, "seeds": len(seeds),
                      "median": statistics.median(got), "floor": statistics.median(floors),
                      "ratio": statistics.median(got / floors) if floors.all() else None,
                      "corr": corr})
    return table


def markdown(table: list[dict], channel: str) -> str:
    def f(v, fmt="{:.1f}", scale=1000.0):
        return "—" if v is None else fmt.format(v * scale)
    lines = [f"max |eY| against the largest localisation error on '{channel}' of the same seed "
             "(mm)", "", "| scenario | controller | seeds | median max \\|eY\\| | median floor | "
             "median ratio | correlation |", "|---|---|---|---|---|---|---|"]
    for r in table:
        lines.append(f"| {r['scenario']} | {r['controller']} | {r['seeds']} | {f(r['median'])} "
                     f"| {f(r['floor'])} | {f(r['ratio'], '{:.2f}', 1.0)} | "
                     f"{f(r['corr'], '{:.2f}', 1.0)} |")
    return "\n".join(lines) + "\n"


def spec_section(path: Path, spec: Path, dt_s: float = 0.01, channel: str = "y") -> str:
    """Markdown: one table per condition of sweep ``spec`` with noise on ``channel`` (the
    localisation floor section of docs/benchmark.md)."""
    with open(path, newline="") as f:
        names = sorted({r["condition"] for r in csv.DictReader(f)})
    parts = []
    for name in names:
        condition = load_condition(f"{spec}#{name}")
        noise = condition.noise
        if channel not in noise:
            continue
        note = ("" if condition.localisation == "none" else
                f"With the localisation filter (`{condition.localisation}`) the controllers "
                "received its estimate, not the raw fix: the floor below is the raw fix's "
                "error, the filter's input, so a ratio below 1 is partly the filter's work.\n\n")
        parts.append(f"### {name}\n\n" + note
                     + markdown(analyse(path, noise, dt_s, channel, name), channel))
    return "\n".join(parts)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("csv", type=Path)
    ap.add_argument("--condition", default="all", help="rows of this condition (default: all)")
    ap.add_argument("--noise", default="realistic",
                    help="the condition whose noise the runs had (a shipped name or a file)")
    ap.add_argument("--channel", default="y")
    ap.add_argument("--dt", type=float, default=0.01, help="the control period (s)")
    a = ap.parse_args(argv)
    if not a.csv.is_file():
        print(f"noise_floor: {a.csv}: no such file", file=sys.stderr)
        return 2
    noise = load_condition(a.noise).noise
    if a.channel not in noise:
        print(f"noise_floor: condition '{a.noise}' has no noise on '{a.channel}'",
              file=sys.stderr)
        return 2
    sys.stdout.write(markdown(analyse(a.csv, noise, a.dt, a.channel, a.condition), a.channel))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
