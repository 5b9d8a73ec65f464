"""Tables 6-8 in both worlds from a robustness sweep: median (worst) over seeds, margins,
and the ranges the fuzzy weights and the horizons covered.

Usage (after ``source ros_ws/env.sh``; ``python tools/make_benchmark.py`` writes the CSV)::

    python tools/paper_tables.py runs/benchmark/results.csv              # docs/paper-tables.md
    python tools/paper_tables.py runs/benchmark/results.csv --out -      # to stdout

The paper scenarios are the bench's ``bench_dlc_60_mu05`` / ``bench_dlc_90_mu06`` (the
paper's lane changes with a 30 s lead-out: every figure covers the lead-out too). The ideal
world is the sweep's ``ideal`` condition (deterministic: one run), the realistic world its
``all`` condition (``config/conditions/realistic.yaml``, over the sweep's seeds). ``lqr_ff``
(the outside reference) and ``improved_np30`` (beyond the paper: improved with N_p 30,
N_c 10) are added to Tables 6 and 7; they are not in the rankings, which are the paper's.
Margins come from ``core.margins`` at the scenario's speed: the ideal loop, and the realistic
condition's delay and steering dead time told to the controller (the sensing noise and the
estimated tyre forces are not in a linear margin).
"""

from __future__ import annotations

import argparse
import csv
import datetime
import sys
from pathlib import Path

import numpy as np

from fourws_bringup.paper import T67_KEYS, TABLES, paper_condition, rank, tie_groups

ROOT = Path(__file__).resolve().parents[1]
#: condition of ``fourws paper`` -> the sweep condition that runs it in the bench
SWEEP_CONDITION = {"ideal": "ideal", "realistic": "all"}
BENCH = {"dlc_60_mu05": "bench_dlc_60_mu05", "dlc_90_mu06": "bench_dlc_90_mu06"}
RANGES = (("q_Y", "q_y"), ("q_φ", "q_phi"), ("r_Δδ", "r_ddelta"), ("r_ΔMz", "r_dmz"),
          ("N_p", "np"), ("N_c", "nc"))
FUZZY = {"improved", "ampc_4ws", "ampc_4ws_dyc", "improved_np30"}
#: beside Tables 6-7, not ranked: the outside reference and the variant beyond the paper
EXTRA = ("lqr_ff", "improved_np30")


def read_rows(path: str | Path) -> list[dict[str, str]]:
    with open(path, encoding="utf-8", newline="") as f:
        return list(csv.DictReader(f))


def pick(rows: list[dict[str, str]], controller: str, scenario: str, condition: str
         ) -> list[dict[str, str]]:
    """The rows of one controller on one paper scenario (by the bench file's stem)."""
    stem = BENCH[scenario]
    return [r for r in rows if r["controller"] == controller and r["condition"] == condition
            and Path(r["scenario"]).stem == stem]


def median_worst(rows: list[dict[str, str]], key: str) -> tuple[float, float]:
    """(median, worst = largest) of ``key`` over the completed runs; NaN when none."""
    v = [float(r[key]) for r in rows if r["completed"] == "True" and r.get(key, "") != ""]
    return (float(np.median(v)), max(v)) if v else (float("nan"), float("nan"))


def _cell(m: float, w: float, n: int) -> str:
    return f"{m:.4f}" if n == 1 else f"{m:.4f} ({w:.4f})"


def margin_text(controller: str, scenario: str, world: str) -> str:
    """ρ / GM / PM / DM at the paper scenario's speed, the world's delays told to the controller
    (the world's condition, as ``paper.margins_line`` takes it)."""
    from fourws_bringup.core.conditions import node_parameters
    from fourws_bringup.core.configs import load_mpc_config
    from fourws_bringup.core.margins import margins
    from fourws_sim.core.scenario import load_scenario

    cond = paper_condition(world)
    sc = load_scenario(scenario)
    m = margins(load_mpc_config(controller, node_parameters(cond)["mpc_node"]), sc.vehicle,
                sc.speed_mps, delay_periods=cond.delay_periods,
                steer_dead_time_s=cond.steer_dead_time_s)
    return f"ρ {m.spectral_radius:.4f} / {m.margins_text()}"


def ranges_text(rows: list[dict[str, str]], controller: str) -> str:
    parts = []
    for label, key in RANGES:
        if label.startswith(("q", "r")) and controller not in FUZZY:
            continue
        lo = [float(r[f"{key}_min"]) for r in rows if r.get(f"{key}_min", "") != ""]
        hi = [float(r[f"{key}_max"]) for r in rows if r.get(f"{key}_max", "") != ""]
        if lo and hi and max(hi) > 0:        # lqr_ff has neither weights nor horizons
            a, b = min(lo), max(hi)
            parts.append(f"{label} {a:.0f}" if round(a) == round(b) else
                         f"{label} {a:.0f}-{b:.0f}")
    return ", ".join(parts)


def tables(rows: list[dict[str, str]], margins: bool = True) -> str:
    out = []
    for world, cond in SWEEP_CONDITION.items():
        out += [f"## {world} world (sweep condition `{cond}`)", ""]
        for title, scenario, paper, keys, heads in TABLES:
            ctrls = list(paper) + (list(EXTRA) if keys is T67_KEYS else [])
            out += [f"### {title} ({world})", "",
                    "| controller | source | " + " | ".join(h.replace("|", "\\|") for h in heads)
                    + " | runs (aborted) | "
                    + ("margins | " if margins else "") + "weights and horizons covered |",
                    "|---|---|" + "---|" * (len(heads) + 2 + int(margins))]
            medians = {}
            for c in ctrls:
                rs = pick(rows, c, scenario, cond)
                if not rs and c in EXTRA:
                    continue
                ok = [r for r in rs if r["completed"] == "True"]
                cells = []
                for k in keys:
                    m, w = median_worst(rs, k)
                    cells.append(_cell(m, w, len(ok)))
                medians[c] = {"completed": len(ok) == len(rs) and bool(rs),
                              "max_abs_lateral_error_m": median_worst(rs, keys[0])[0]}
                mg = f"{margin_text(c, scenario, world)} | " if margins else ""
                out.append(f"| {c} | fourws | " + " | ".join(cells)
                           + f" | {len(rs)} ({len(rs) - len(ok)}) | {mg}"
                           + f"{ranges_text(rs, c)} |")
                if c in paper:
                    out.append(f"| {c} | paper | " + " | ".join(f"{v:.5f}" for v in paper[c])
                               + " | | " + ("| " if margins else "") + "|")
            order = rank({c: medians[c] for c in paper}, "max_abs_lateral_error_m")
            groups = tie_groups({c: medians[c] for c in paper}, order,
                                "max_abs_lateral_error_m")
            paper_order = sorted(paper, key=lambda c: paper[c][0])
            out += ["", "Ranking on the median max |eY| (best first; ties within 1 %): "
                    + " < ".join(" ≈ ".join(g) for g in groups)
                    + f"; paper {' < '.join(paper_order)}", ""]
    return "\n".join(out)


def page(csv_path: str) -> str:
    """docs/paper-tables.md: its header (the seeds from the rows, the told delays from the
    realistic condition), then :func:`tables`."""
    rows = read_rows(csv_path)
    seeds = sorted({int(r["seed"]) for r in rows if r["condition"] == SWEEP_CONDITION[
        "realistic"]})
    cond = paper_condition("realistic")
    told = (f"{cond.delay_periods} period{'s' if cond.delay_periods != 1 else ''} + "
            f"{1e3 * cond.steer_dead_time_s:g} ms")
    head = (
        "# Tables 6-8 in both worlds (generated)\n\n"
        f"Generated {datetime.date.today()} by `python tools/paper_tables.py "
        "runs/benchmark/results.csv` from the robustness sweep of `docs/benchmark.md` "
        "(in-process loop; the paper scenarios with their 30 s lead-out, so every figure covers "
        "the lead-out too). Ideal: one deterministic run. Realistic (`all`): median (worst) over "
        f"seeds {_span(seeds)}. ρ / GM / PM (phase lag) / DM (delay margin) from `fourws "
        f"margins` (realistic: {told} told to the controller). `lqr_ff` (outside reference) and "
        "`improved_np30` (beyond the paper) stand beside Tables 6-7 and are not ranked. The "
        "MPC presets carry the LQR terminal cost (beyond the paper; `mpc_fws`'s prices Y's "
        "level alone, `docs/mpc.md`); every preset's scaling is the tuning procedure's "
        "(`docs/bench.md`, \"Tuning\"). Reading: `docs/results.md`.\n\n")
    return head + tables(rows) + "\n"


def _span(seeds: list[int]) -> str:
    """``0-4`` for consecutive seeds, else a comma list."""
    if seeds and seeds == list(range(seeds[0], seeds[-1] + 1)) and len(seeds) > 1:
        return f"{seeds[0]}-{seeds[-1]}"
    return ", ".join(map(str, seeds))


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("csv", help="the robustness sweep's results.csv")
    ap.add_argument("--out", default=str(ROOT / "docs" / "paper-tables.md"),
                    help="where to write the page ('-': stdout)")
    args = ap.parse_args(argv)
    text = page(args.csv)
    if args.out == "-":
        sys.stdout.write(text)
    else:
        Path(args.out).write_text(text, encoding="utf-8")
        print(f"{args.out} written", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
