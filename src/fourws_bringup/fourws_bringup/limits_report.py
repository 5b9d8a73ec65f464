"""The limit bench's report (docs/limits.md) from its sweep rows: pure tables, no plots.

Its rules are :data:`RULES`, stated once and printed in the report (docs/limits.md,
"Metrics and rules").
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any, NamedTuple

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


#: the bench's targets are judged in the realistic world, each controller as shipped
TARGET_CONDITION = "realistic_shipped"
#: the lane-change ladders (DLC on μ 0.5 and 0.9)
DLC_LADDERS = ("ladder_dlc_60_mu05_", "ladder_dlc_60_mu09_")


class Target(NamedTuple):
    """One target of the bench: its ``key``, what it asks, what the rows show, and whether
    it is met (never met without rows to judge it on)."""

    key: str
    goal: str
    measured: str
    met: bool


def _runs(by_case: dict, controller: str, condition: str, prefix: str = "",
          rungs: tuple[float, float] = (-math.inf, math.inf)) -> list[dict]:
    """The runs of a controller under a condition on the scenarios starting with ``prefix``,
    a ladder's within ``rungs`` (closed)."""
    return [r for (c, sc, cd), rs in by_case.items() for r in rs
            if c == controller and cd == condition and sc.startswith(prefix)
            and (not sc.startswith(("ladder", "iso"))
                 or rungs[0] <= rung_value(sc) <= rungs[1])]


def _max(runs: Sequence[dict], key: str) -> float:
    v = [x for x in (_num(r.get(key)) for r in runs) if math.isfinite(x)]
    return max(v) if v else math.nan


def _clean_count(runs: Sequence[dict]) -> str:
    return f"{sum(_truthy(r.get('completed_clean')) for r in runs)}/{len(runs)} clean"


def _demand(by_case: dict, prefix: str, rung: float) -> float:
    """The median peak demand (μg) of a ladder's rung."""
    return median([r for (_, sc, _), rs in by_case.items() for r in rs
                   if sc.startswith(prefix) and rung_value(sc) == rung], "demand_mug")


def targets(by_case: dict, alloc_shipped: str, alloc_baseline: str = "production"
            ) -> list[Target]:
    """Each target of the limit bench, judged on the rows under :data:`TARGET_CONDITION`
    (improved's own allocation ``realistic_<alloc_shipped>`` counted as shipped too; on
    split-μ braking ``alloc_baseline`` is shown beside it, not judged)."""
    cd = TARGET_CONDITION
    out = []
    twins = [t for t in twin_failures(by_case) if f"({cd}) where " in t]
    n_dyc = sum(1 for (c, _, ccd) in by_case if c in TWINS and ccd == cd)
    out.append(Target("dyc_twins", "no preset with DYC fails a case its twin without DYC "
                      "completes", f"such cases: {len(twins)} of {n_dyc}"
                      + (" (" + "; ".join(twins) + ")" if twins else ""),
                      n_dyc > 0 and not twins))
    runs = _runs(by_case, "improved", cd) + _runs(by_case, "improved", f"realistic_{alloc_shipped}")
    spins = sum(_truthy(r.get("spin")) for r in runs)
    out.append(Target("never_spins", "improved never spins",
                      f"{spins} spins in {len(runs)} runs", bool(runs) and spins == 0))
    dlc = [r for p in DLC_LADDERS for r in _runs(by_case, "improved", cd, p, (0.0, 1.0))]
    rungs = sorted({rung_value(sc) for (c, sc, ccd) in by_case
                    if c == "improved" and ccd == cd and sc.startswith(DLC_LADDERS)})
    upto = max((v for v in rungs if v <= 1.0), default=None)
    nxt = min((v for v in rungs if v > 1.0), default=None)
    beta = _max(dlc, "max_abs_sideslip_deg")
    above = ""
    if nxt is not None and upto != 1.0:     # the ladder has no 1.0 rung: the next one shown
        over = [r for p in DLC_LADDERS for r in _runs(by_case, "improved", cd, p, (nxt, nxt))]
        above = (f"; the ladder has no 1.0 μg rung, at {fmt(nxt)} μg: {_clean_count(over)}, "
                 f"max abs β {fmt(_max(over, 'max_abs_sideslip_deg'), '°')}")
    out.append(Target("dlc_1g", "improved completes the DLC through 1.0 μg on μ 0.5 and 0.9, "
                      "in lane, max abs β ≤ 3°",
                      f"rungs up to {fmt(upto)} μg: {_clean_count(dlc)}, max abs β "
                      f"{fmt(beta, '°')}{above}",
                      bool(dlc) and all(_truthy(r.get("completed_clean")) for r in dlc)
                      and beta <= 3.0))
    iso = LADDERS["ISO 3888-2 μ 0.9"]
    best = {c: headline(by_case, c, cd, iso)[0] for c in CONTROLLERS}
    others = max((v for c, v in best.items() if c != "improved" and v is not None),
                 default=None)
    mine = best["improved"]
    tie = " (a tie)" if mine is not None and mine == others else ""
    out.append(Target("iso3888_2", "improved passes the highest ISO 3888-2 entry speed of any "
                      "preset", f"improved {fmt(mine, ' km/h', 0)}, the best other "
                      f"{fmt(others, ' km/h', 0)}{tie}",
                      mine is not None and (others is None or mine >= others)))
    ch = paired_change(by_case, "improved", "ampc_4ws", cd, "max_abs_sideslip_deg")
    raised = []
    for name, prefix in LADDERS.items():
        a = headline(by_case, "improved", cd, prefix)[0]
        b = headline(by_case, "ampc_4ws", cd, prefix)[0]
        if a is not None and (b is None or a > b) and _demand(by_case, prefix, a) >= 0.9:
            dig = 2 if prefix.startswith("ladder") else 0
            raised.append(f"{name} {fmt(b, '', dig)} → {fmt(a, '', dig)}")
    med = float(np.median(ch)) if ch else math.nan
    out.append(Target("dyc_keep", "DYC earns its keep at ≥ 0.9 μg: improved against ampc_4ws "
                      "lowers max abs β by ≥ 25 % over paired seeds, or raises the highest "
                      "rung passed to one of ≥ 0.9 μg",
                      f"median change {fmt(100 * med, ' %', 0)} over {len(ch)} pairs; rung "
                      "raised: " + (", ".join(raised) if raised else "none"),
                      (math.isfinite(med) and med <= -0.25) or bool(raised)))
    lqr = sorted(sc for (c, sc, ccd), rs in by_case.items()
                 if c == "lqr_ff" and ccd == cd and clean(rs))
    misses = [sc for sc in lqr if not clean(by_case.get(("mpc_fws", sc, cd), []))]
    out.append(Target("fws_baseline", "wherever lqr_ff stays clean, mpc_fws does too",
                      f"cases where it does not: {len(misses)} of {len(lqr)}"
                      + (" (" + ", ".join(misses) + ")" if misses else ""),
                      bool(lqr) and not misses))
    cells, ok = [], False
    for method in dict.fromkeys((alloc_shipped, alloc_baseline)):    # once each
        rs = by_case.get(("improved", "split_mu_braking_80_20", f"realistic_{method}"), [])
        if method == alloc_shipped:
            ok = bool(rs) and all(_truthy(r.get("completed_clean")) for r in rs)
        cells.append(f"{method} {_clean_count(rs)}, max abs heading error "
                     f"{fmt(median(rs, 'max_abs_heading_error_deg'), '°')}, braking "
                     f"{fmt(median(rs, 'braking_distance_m'), ' m', 1)}")
    out.append(Target("split_mu", f"split-μ braking completes (improved's allocation, "
                      f"{alloc_shipped}; {alloc_baseline}, the fair baseline, beside it)",
                      "; ".join(cells), ok))
    return out


def targets_table(rows: Sequence[Target]) -> str:
    """:func:`targets` as a Markdown table."""
    lines = ["| target | measured | met |", "|---|---|---|"]
    lines += [f"| {t.goal} | {t.measured} | {'yes' if t.met else '**no**'} |" for t in rows]
    return "\n".join(lines) + "\n"
