"""The limit bench's report (docs/limits.md) from its sweep rows: pure tables, no plots.

Its rules are :data:`RULES`, stated once and printed in the report (docs/limits.md,
"Metrics and rules").
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

#: the report's rules, one sentence each (printed in docs/limits.md, "Metrics and rules")
RULES = (
    "a **case** is one scenario under one condition for one controller; it is **clean** when "
    "every seed's run completed without a spin and without a cone or lane violation "
    "(``core.limit_metrics``); a realistic case has five seeds, an ideal one one;",
    "a controller's **headline** on a ladder is the highest rung whose case is clean, with "
    "every rung below it clean too (a rung passed above a failed one is shown, not counted);",
    "**DYC's effect**: paired seeds (same scenario, condition and seed), improved against "
    "ampc_4ws (the same MPC without DYC), on rungs of at least 0.9 μg: the median and range of "
    "the relative change of max |β| over the pairs.",
)
CONTROLLERS = ("mpc_fws", "mpc_4ws", "ampc_4ws", "ampc_4ws_dyc", "improved", "lqr_ff")
#: DYC presets and their twin without DYC
TWINS = {"improved": "ampc_4ws", "ampc_4ws_dyc": "ampc_4ws"}
LADDERS = {"DLC μ 0.5": "ladder_dlc_60_mu05_", "DLC μ 0.9": "ladder_dlc_60_mu09_",
           "ISO 3888-1 μ 0.9": "iso3888_1_", "ISO 3888-2 μ 0.9": "iso3888_2_"}


def scenario_name(path: str) -> str:
    """A scenario's file stem (``limits/x.yaml`` → ``x``)."""
    return Path(str(path)).stem


def rung_value(name: str) -> float:
    """The ladder position of a scenario name: its demand (``_130``: 1.30) or its entry
    speed (``iso3888_2_55_mu09``: 55)."""
    parts = name.split("_")
    if name.startswith("ladder"):
        return int(parts[-1]) / 100.0
    return float(parts[2])


def _truthy(v: Any) -> bool:
    return v is True or str(v) == "True"


def _num(v: Any) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        return math.nan
    return x


def cases(rows: Iterable[dict[str, Any]]) -> dict[tuple[str, str, str], list[dict]]:
    """Rows grouped by (controller, scenario name, condition)."""
    out: dict[tuple[str, str, str], list[dict]] = defaultdict(list)
    for r in rows:
        out[(str(r["controller"]), scenario_name(r["scenario"]), str(r["condition"]))].append(r)
    return dict(out)


def with_shipped(by_case: dict, shipped: dict[str, str]) -> dict:
    """``by_case`` plus, per world, a ``<world>_shipped`` condition: each controller's runs
    under the condition of its shipped prediction model (``shipped``: controller → the
    condition suffix, ``linear`` or ``friction``; a controller without one, a law of its
    own, under the plain world)."""
    out = dict(by_case)
    for (c, sc, cd), runs in by_case.items():
        for world in ("ideal", "realistic"):
            model = shipped.get(c)
            if cd == (f"{world}_{model}" if model else world):
                out[(c, sc, f"{world}_shipped")] = runs
    return out


def clean(runs: Sequence[dict]) -> bool:
    """Every run of the case completed clean (module docstring)."""
    return bool(runs) and all(_truthy(r.get("completed_clean")) for r in runs)


def headline(by_case: dict, controller: str, condition: str, prefix: str
             ) -> tuple[float | None, list[float]]:
    """(highest clean rung with every rung below clean, or None; the rungs failed)."""
    rungs = sorted({rung_value(sc) for (c, sc, cd) in by_case
                    if c == controller and cd == condition and sc.startswith(prefix)})
    best, failed, broken = None, [], False
    for v in rungs:
        runs = [r for (c, sc, cd), rs in by_case.items() for r in rs
                if c == controller and cd == condition and sc.startswith(prefix)
                and rung_value(sc) == v]
        if clean(runs):
            if not broken:
                best = v
        else:
            broken = True
            failed.append(v)
    return best, failed


def median(runs: Sequence[dict], key: str) -> float:
    v = [_num(r.get(key)) for r in runs]
    v = [x for x in v if math.isfinite(x)]
    return float(np.median(v)) if v else math.nan


def paired_change(by_case: dict, a: str, b: str, condition: str, key: str,
                  min_demand: float = 0.9) -> list[float]:
    """(a − b)/b of ``key`` over seed pairs on ladder rungs ≥ ``min_demand`` μg."""
    out = []
    for (c, sc, cd), runs in by_case.items():
        if c != a or cd != condition or not sc.startswith("ladder"):
            continue
        if rung_value(sc) < min_demand:
            continue
        twin = {r["seed"]: r for r in by_case.get((b, sc, cd), [])}
        for r in runs:
            t = twin.get(r["seed"])
            if t is None:
                continue
            va, vb = _num(r.get(key)), _num(t.get(key))
            if math.isfinite(va) and math.isfinite(vb) and vb > 0:
                out.append((va - vb) / vb)
    return out


def twin_failures(by_case: dict) -> list[str]:
    """Cases a DYC preset fails (not clean) that its no-DYC twin completes clean, under the
    same condition."""
    out = []
    for (c, sc, cd), runs in sorted(by_case.items()):
        twin = TWINS.get(c)
        if twin is None or (twin, sc, cd) not in by_case:
            continue
        if not clean(runs) and clean(by_case[(twin, sc, cd)]):
            out.append(f"{c} fails {sc} ({cd}) where {twin} completes")
    return out


def fmt(v: float | None, unit: str = "", digits: int = 2) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "—"
    return f"{v:.{digits}f}{unit}"


def headline_table(by_case: dict, conditions: Sequence[str]) -> str:
    """Per controller and condition: the headline of each ladder and the spins."""
    head = " | ".join(f"{k} (failed above)" for k in LADDERS)
    lines = [f"| controller | condition | {head} | spins |",
             "|---|---|" + "---|" * len(LADDERS) + "---|"]
    for cd in conditions:
        for c in CONTROLLERS:
            runs = [r for (cc, _, ccd), rs in by_case.items() for r in rs
                    if cc == c and ccd == cd]
            if not runs:
                continue
            cells = []
            for prefix in LADDERS.values():
                best, failed = headline(by_case, c, cd, prefix)
                unit = " μg" if prefix.startswith("ladder") else " km/h"
                dig = 2 if prefix.startswith("ladder") else 0
                extra = (" (" + ", ".join(fmt(f, "", dig) for f in failed) + ")") if failed \
                    else ""
                cells.append((fmt(best, unit, dig) if best is not None else "none") + extra)
            spins = sum(_truthy(r.get("spin")) for r in runs)
            lines.append(f"| {c} | {cd} | " + " | ".join(cells) + f" | {spins}/{len(runs)} |")
    return "\n".join(lines) + "\n"


def degradation_table(by_case: dict, condition: str, prefix: str) -> str:
    """Median max |e_Y| (m) / max |β| (°) per controller and rung, and clean runs."""
    rungs = sorted({rung_value(sc) for (_, sc, cd) in by_case
                    if cd == condition and sc.startswith(prefix)})
    lines = ["| controller | " + " | ".join(fmt(v, "", 2 if prefix.startswith("ladder")
                                                   else 0) for v in rungs) + " |",
             "|---|" + "---|" * len(rungs)]
    for c in CONTROLLERS:
        cells = []
        for v in rungs:
            runs = [r for (cc, sc, cd), rs in by_case.items() for r in rs
                    if cc == c and cd == condition and sc.startswith(prefix)
                    and rung_value(sc) == v]
            if not runs:
                cells.append("—")
                continue
            n_clean = sum(_truthy(r.get("completed_clean")) for r in runs)
            cells.append(f"{fmt(median(runs, 'max_abs_lateral_error_m'))} / "
                         f"{fmt(median(runs, 'max_abs_sideslip_deg'), '°', 1)} "
                         f"({n_clean}/{len(runs)})")
        lines.append(f"| {c} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def case_table(by_case: dict, scenario: str, conditions: Sequence[str],
               keys: Sequence[tuple[str, str, int]]) -> str:
    """Medians of ``keys`` ((column, key, digits)) per controller/condition of one
    scenario."""
    lines = ["| controller | condition | clean | " + " | ".join(k[0] for k in keys) + " |",
             "|---|---|---|" + "---|" * len(keys)]
    for (c, sc, cd), runs in sorted(by_case.items()):
        if sc != scenario or cd not in conditions:
            continue
        n_clean = sum(_truthy(r.get("completed_clean")) for r in runs)
        vals = " | ".join(fmt(median(runs, k), "", d) for _, k, d in keys)
        lines.append(f"| {c} | {cd} | {n_clean}/{len(runs)} | {vals} |")
    return "\n".join(lines) + "\n"


def adaptive_table(by_case: dict, controller: str, condition: str, prefix: str) -> str:
    """What the adaptive parts did per rung: N_p and N_c range, each weight's range."""
    keys = (("N_p", "np"), ("N_c", "nc"), ("q_Y", "q_y"), ("q_φ", "q_phi"),
            ("R_Δδ", "r_ddelta"), ("R_ΔMz", "r_dmz"))
    lines = ["| rung | " + " | ".join(k for k, _ in keys) + " |",
             "|---|" + "---|" * len(keys)]
    for (c, sc, cd), runs in sorted(by_case.items(), key=lambda kv: rung_value(kv[0][1])
                                    if kv[0][1].startswith(prefix) else 0):
        if c != controller or cd != condition or not sc.startswith(prefix):
            continue
        cells = []
        for _, k in keys:
            lo = min(_num(r.get(f"{k}_min")) for r in runs)
            hi = max(_num(r.get(f"{k}_max")) for r in runs)
            dig = 0 if k in ("np", "nc") or hi >= 100 else 2
            cells.append(f"{fmt(lo, '', dig)}–{fmt(hi, '', dig)}")
        lines.append(f"| {fmt(rung_value(sc))} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
