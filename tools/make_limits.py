"""Run the limit-handling bench (benchmarks/limits.yaml) and write docs/limits.md with its
figures (docs/limits/*.png).

    python tools/make_limits.py [--workers 2] [--from-csv runs/limits/results.csv]

The tables come from ``fourws_bringup.limits_report`` (its docstring states the rules); the
figures re-run a few cases in process (the same loop as the sweep).
"""

from __future__ import annotations

import argparse
import datetime
import subprocess
import sys
from pathlib import Path

import numpy as np

from fourws_bringup import limits_report as L
from fourws_bringup.sweep import load_spec, read_csv, run_sweep, write_csv

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "benchmarks" / "limits.yaml"
MODELS = ("ideal_linear", "ideal_friction", "realistic_linear", "realistic_friction")
SHIPPED = ("ideal_shipped", "realistic_shipped")
ALLOC = ("ideal_optimal", "ideal_optimal_bounded", "ideal_rule", "ideal_production",
         "realistic_optimal", "realistic_optimal_bounded", "realistic_rule",
         "realistic_production", "realistic_optimal_noslip", "realistic_production_noslip")


def _job(jobs, controller: str, scenario: str, condition: str, seed: int = 0):
    for j in jobs:
        if (j.controller == controller and L.scenario_name(j.scenario) == scenario
                and j.condition.name == condition and j.condition.seed == seed):
            return j
    raise LookupError(f"{controller} {scenario} {condition} {seed}")


def figures(jobs, out_dir: Path) -> list[str]:
    """Paths through the ISO 3888-2 cones and the β-r phase plane; the files written."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fourws_bringup.core.closed_loop import run_closed_loop

    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    cases = [("improved", "realistic_friction"), ("improved", "realistic_linear"),
             ("ampc_4ws", "realistic_friction"), ("mpc_4ws", "realistic_linear")]
    fig, ax = plt.subplots(figsize=(9, 3.6))
    lanes = ()
    for c, cd in cases:
        j = _job(jobs, c, "iso3888_2_40_mu09", cd)
        log = run_closed_loop(j.scenario, j.controller, condition=j.condition)
        lanes = log.lanes
        ax.plot(log.state["x"], log.state["y"], label=f"{c}, {cd}")
    for x0, x1, yc, w in lanes:
        for edge in (yc - w / 2, yc + w / 2):
            ax.plot([x0, x1], [edge, edge], "k-", lw=2)
            ax.plot([x0, x1], [edge, edge], "o", color="tab:orange", ms=4)
    ax.set(xlim=(-10, 75), xlabel="X (m)", ylabel="Y (m)",
           title="ISO 3888-2 at 40 km/h, μ 0.9 (1.0 μg), realistic, seed 0: CG paths and cones")
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    path = out_dir / "iso3888_2_paths.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    written.append(path.name)

    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, sc in zip(axes, ("ladder_dlc_60_mu05_130", "ladder_dlc_60_mu09_130"),
                      strict=True):
        mu = 0.5 if "mu05" in sc else 0.9
        for c, cd in (("improved", "realistic_friction"), ("improved", "realistic_linear"),
                      ("ampc_4ws", "realistic_friction")):
            j = _job(jobs, c, sc, cd)
            log = run_closed_loop(j.scenario, j.controller, condition=j.condition)
            ax.plot(np.degrees(log.state["sideslip"]), log.state["yaw_rate"], lw=0.8,
                    label=f"{c}, {cd}")
        r_lim = mu * 9.81 / (60 / 3.6)
        ax.axhline(r_lim, color="k", ls="--", lw=0.8)
        ax.axhline(-r_lim, color="k", ls="--", lw=0.8)
        ax.set(xlabel="β (deg)", title=f"{sc}: β–r (dashed: μ g / v_x)", xlim=(-15, 15))
    axes[0].set_ylabel("r (rad/s)")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    path = out_dir / "phase_plane.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    written.append(path.name)
    return written


def demand_table(by_case) -> str:
    lines = ["| scenario | peak demand (μg, of the lowest μ) |", "|---|---|"]
    seen = {}
    for (_, sc, _), runs in by_case.items():
        seen.setdefault(sc, L.median(runs, "demand_mug"))
    for sc in sorted(seen, key=lambda s: (s.split("_")[0], L.rung_value(s)
                                          if s.startswith(("ladder", "iso")) else 0)):
        lines.append(f"| {sc} | {L.fmt(seen[sc])} |")
    return "\n".join(lines) + "\n"


def dyc_lines(by_case) -> list[str]:
    out = []
    for cd in (*SHIPPED, *MODELS):
        for a in ("improved", "ampc_4ws_dyc"):
            ch = L.paired_change(by_case, a, "ampc_4ws", cd, "max_abs_sideslip_deg")
            if ch:
                out.append(f"| {a} vs ampc_4ws | {cd} | {len(ch)} | "
                           f"{100 * float(np.median(ch)):+.0f} % | "
                           f"{100 * min(ch):+.0f} … {100 * max(ch):+.0f} % |")
    return ["| pair | condition | pairs | median change of max abs β | range |",
            "|---|---|---|---|---|", *out]


def fws_mechanism(goals) -> list[str]:
    """Where the front-steer target is missed, where its mechanism is measured."""
    missed = any(not g.met for g in goals if g.key == "fws_baseline")
    return ["Why `mpc_fws` misses where `lqr_ff` passes (its tuning's grip constraint, the "
            "scalings that would pass, what they cost): `docs/results.md`, \"Front steer at its "
            "limit\", and `studies/fws_at_the_limit/README.md`.", ""] if missed else []


def fws_lines(by_case) -> list[str]:
    out = []
    for cd in SHIPPED:
        for (c, sc, ccd), runs in sorted(by_case.items()):
            if c != "lqr_ff" or ccd != cd:
                continue
            fws = by_case.get(("mpc_fws", sc, cd), [])
            if L.clean(runs) and fws and not L.clean(fws):
                out.append(f"- {sc} ({cd}): lqr_ff clean, mpc_fws "
                           f"{sum(L._truthy(r.get('completed_clean')) for r in fws)}/"
                           f"{len(fws)} clean, median max abs e_Y "
                           f"{L.fmt(L.median(fws, 'max_abs_lateral_error_m'))} m")
    return out or ["- none: wherever lqr_ff stays in lane, so does mpc_fws"]


def commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                              capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--from-csv", help="tabulate these rows instead of running the sweep")
    ap.add_argument("--out", default=str(ROOT / "docs" / "limits.md"))
    args = ap.parse_args()
    jobs = load_spec(SPEC)
    if args.from_csv:
        rows = read_csv(Path(args.from_csv))
    else:
        rows = run_sweep(jobs, args.workers)
        (ROOT / "runs" / "limits").mkdir(parents=True, exist_ok=True)
        write_csv(rows, ROOT / "runs" / "limits" / "results.csv")
    out = Path(args.out)
    figs = figures(jobs, out.parent / "limits")
    out.write_text(page(rows, figs), encoding="utf-8")
    raised = _raised(rows)
    print(f"{out}: {len(rows)} runs, {len(raised)} raised")
    return 0 if not raised else 1


def _raised(rows: list[dict]) -> list[dict]:
    return [r for r in rows if str(r.get("reason", "")).startswith("raised")]


def page(rows: list[dict], figs: list[str]) -> str:
    """docs/limits.md from the sweep's rows and the figure files in docs/limits/."""
    from fourws_bringup.core.configs import load_allocator_config, load_mpc_config

    raised = _raised(rows)
    shipped = {c: ("friction" if load_mpc_config(c).prediction_model == "single_track_friction"
                   else "linear") for c in L.CONTROLLERS if c != "lqr_ff"}
    by_case = L.with_shipped(L.cases(rows), shipped)
    twins = L.twin_failures(by_case)
    goals = L.targets(by_case, load_allocator_config("improved").method)
    alloc_keys = (("max abs e_Y m", "max_abs_lateral_error_m", 3),
                  ("max abs heading error deg", "max_abs_heading_error_deg", 2),
                  ("max abs β deg", "max_abs_sideslip_deg", 2),
                  ("braking distance m", "braking_distance_m", 1),
                  ("unmet M_z N·m", "unmet_mz_max_nm", 0),
                  ("unmet F_x N", "unmet_fx_max_n", 0))
    text = [
        "# Limit handling: the bench and what it shows",
        "",
        f"Generated by `make limits` (`python tools/make_limits.py --workers 2`) from "
        f"`benchmarks/limits.yaml`, commit {commit()}, {datetime.date.today()}: "
        f"{len(rows)} runs, {len(raised)} raised. Seeds 0-4 under the realistic condition, one "
        "run in the ideal world. Nothing in it is tuned.",
        "",
        "## What it runs",
        "The paper's five presets and `lqr_ff` (not `improved_np30`) on the tanh double lane "
        "change at 60 km/h, stretched to a ladder of "
        "0.6-1.3 μg peak demand on μ 0.5 and 0.9; ISO 3888-1 at 60-80 km/h and ISO 3888-2 "
        "(obstacle avoidance, lane widths from the car's 1.5 m width as the standard gives "
        "them, cones as lane boundaries) at 30-45 km/h on μ 0.9, speed held; a split-μ lane "
        "change (0.9 | 0.5) and a μ drop from 0.9 to 0.6 in a 45 m corner. Each case runs "
        "with the prediction's tyres linear (`single_track_relaxation`, the conventional "
        "presets' model) and friction-aware (`single_track_friction`, the adaptive presets' "
        "model), in the ideal and the realistic world (`conditions/realistic.yaml`). Then "
        "improved with each allocation method on split-μ braking (0.9 | 0.3, 80 → 20 km/h "
        "at 4 m/s²) and the hardest cases.",
        "",
        "The ISO courses are tracked along a fixed centre line that keeps a 1.5 m wide body "
        "0.1 m inside the cones at the lane ends (`paths.cone_steepness`); a driver uses the "
        "lanes' width instead, so their speeds are not a test report's. A cone counts as hit "
        "when the body's width around the CG crosses a lane edge; the yawed footprint is not "
        "checked.",
        "",
        "In the ideal world the controllers take μ and the tyre forces from the plant. Under "
        "the realistic condition they take nothing from it: the MPC estimates μ from the "
        "lateral acceleration against its tyre model (`grip.py`; it holds the estimate while "
        "|a_x| exceeds 0.31 μ̂ g or the speed is below 10 m/s), the allocator assumes μ 0.8 and "
        "estimates the loads from the accelerations. In both worlds a wheel-slip limiter "
        "after the allocation (`slip_control.py`: a car's ABS and traction control, rear "
        "axle select-low) scales a wheel's torque down from 10 % to 25 % slip; `..._noslip` "
        "conditions turn it off.",
        "",
        "### Demand",
        demand_table(by_case),
        "### Metrics and rules",
        "Per run (`fourws_bringup/core/limit_metrics.py`): max |β|; max |r| over μ g/v_x; "
        "**spin** when |β| reaches 10° or the run aborts on sideslip; a **cone violation** "
        "when the body's 1.5 m width around the CG reaches beyond a lane's cones while the "
        "CG is in the lane (ISO courses); elsewhere a **lane violation** when max "
        "|e_Y| exceeds 0.275 m, the free half-width of the ISO 3888-1 side lane; the speed "
        "error; the unmet F_x and M_z (demanded against what the wheel torques deliver); the "
        "braking distance. Rules:",
        "",
        *[f"* {rule}" for rule in L.RULES],
        "",
        "## Targets",
        f"Each controller as shipped, in the realistic world ({L.TARGET_CONDITION}, and "
        "improved's own allocation runs; `limits_report.targets` states how each is judged; "
        "a target without runs to judge it on is not met):",
        "",
        L.targets_table(goals),
        *fws_mechanism(goals),
        "No regression on the paper's manoeuvres is judged on their own bench (`make run`, "
        "`docs/results.md`).",
        "",
        "## Headline: highest rung or speed passed clean",
        "As shipped (" + ", ".join(f"{c}: {m}" for c, m in shipped.items()) + " tyres; lqr_ff "
        "its own law):",
        "",
        L.headline_table(by_case, SHIPPED),
        "Every preset with either prediction model:",
        "",
        L.headline_table(by_case, MODELS),
        "## Beyond the limit: how each degrades",
        "Median max |e_Y| (m) / max |β| over seeds, and the clean runs.",
        "",
    ]
    for cd in ("realistic_shipped", "realistic_friction", "realistic_linear"):
        for name, prefix in L.LADDERS.items():
            text += [f"### {name}, {cd}", L.degradation_table(by_case, cd, prefix)]
    text += [
        "### Split-μ lane change and μ drop in a corner",
        L.case_table(by_case, "split_mu_dlc_60", (*MODELS, *SHIPPED), alloc_keys[:3]),
        L.case_table(by_case, "mu_drop_corner_60", (*MODELS, *SHIPPED), alloc_keys[:3]),
        "## Does DYC earn its keep?",
        "Paired seeds on ladder rungs of at least 0.9 μg (negative: DYC lowers max |β|).",
        "",
        *dyc_lines(by_case),
        "",
        "Cases a DYC preset fails where its twin without DYC completes clean:",
        "",
        *(f"- {t}" for t in twins), *([] if twins else ["- none"]),
        "",
        "## The front-steer baseline against the textbook LQR",
        "mpc_fws runs without the hard β and yaw-rate bounds (its preset says why: a "
        "front-steer car cannot hold β and r apart, and the bounds cap its lateral "
        "acceleration below the friction limit), as lqr_ff; every preset with rear steer "
        "keeps them. Cases where lqr_ff stays clean and mpc_fws does not:",
        "",
        *fws_lines(by_case),
        "",
        "## Allocation",
        "improved with each method (`production`: drive split by static axle load, brake by "
        "a 65 % front balance, what a car already does).",
        "",
    ]
    for sc in ("split_mu_braking_80_20", "ladder_dlc_60_mu05_110", "ladder_dlc_60_mu05_130",
               "iso3888_2_40_mu09"):
        text += [f"### {sc}", L.case_table(by_case, sc, ALLOC, alloc_keys)]
    text += ["## What the adaptive parts did (improved, realistic_friction)"]
    for name, prefix in L.LADDERS.items():
        if prefix.startswith("ladder_"):                     # the lane-change ladders
            text += [f"### {name}", L.adaptive_table(by_case, "improved",
                                                     "realistic_friction", prefix)]
    text += [
        "## Figures",
        *(f"![{f}](limits/{f})" for f in figs),
        "",
    ]
    if raised:
        text += ["## Runs that raised", *(f"- {r['controller']} {r['scenario']} "
                                          f"{r['condition']} {r['seed']}: {r['reason']}"
                                          for r in raised[:20])]
    return "\n".join(text) + "\n"


if __name__ == "__main__":
    sys.exit(main())
