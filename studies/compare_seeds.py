#!/usr/bin/env python3
"""Paired comparison of controllers over seeds, from a ``fourws sweep`` results.csv.

    python studies/compare_seeds.py runs/lqr-comparison/results.csv --reference lqr_ff
        [--metric max_abs_lateral_error_m] [--condition all]
    python studies/compare_seeds.py RESULTS --between all_ekf all_ekf_retuned
    python studies/compare_seeds.py RESULTS --condition sY_x4 --reference lqr_ff \
        --reference-condition all

For every scenario and every other controller: the median and worst of the metric, and,
paired by seed against the reference (with ``--between BASE OTHER``: each controller under
condition OTHER against itself under BASE), the median difference, how many seeds the
controller is better (smaller) on, the two-sided Wilcoxon signed-rank p (scipy; no
normality assumed) and the mean paired difference with its 95 % confidence interval
(Student t: how much better or worse the data allow, not only whether they differ).
Markdown on stdout. Only completed runs of seeds both controllers have are paired; a seed
with a run that did not complete is counted as lost for that controller.

With ``--reference-condition REF_COND`` the reference's runs come from condition REF_COND
and the other controllers' from ``--condition`` (a diagnostic that varies a controller's
parameters through its conditions against one reference run under the shipped condition).

With ``--margin M`` (in the metric's unit, declared before the data are seen): a
non-inferiority test, H0 "the controller is worse by M or more" (mean paired difference
≥ M) against H1 "worse by less than M", one-sided paired t-test at 2.5 %; it rejects H0
exactly when the upper end of the 95 % interval above lies below M.
"""

from __future__ import annotations

import argparse
import csv
import statistics
import sys
from collections import defaultdict
from pathlib import Path

from scipy.stats import ttest_1samp, wilcoxon


def read_rows(path: Path, metric: str, condition: str | None
              ) -> dict[tuple[str, str], dict[int, float | None]]:
    """(scenario, controller) -> seed -> metric (None: the run did not complete)."""
    out: dict[tuple[str, str], dict[int, float | None]] = defaultdict(dict)
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            if condition is not None and r["condition"] != condition:
                continue
            done = r.get("completed", "True") == "True"
            value = float(r[metric]) if done and r.get(metric) not in (None, "") else None
            out[(Path(r["scenario"]).stem, r["controller"])][int(r["seed"])] = value
    return out


def compare(rows: dict[tuple[str, str], dict[int, float | None]], reference: str,
            margin: float | None = None) -> list[dict]:
    """One dict per (scenario, controller other than the reference); with ``margin`` also
    ``p_noninferior`` (one-sided p of H0: mean difference ≥ margin)."""
    table = []
    for scenario in sorted({s for s, _ in rows}):
        ref = rows.get((scenario, reference))
        if ref is None:
            continue
        for (s, c), runs in sorted(rows.items()):
            if s == scenario and c != reference:
                table.append(paired(scenario, c, runs, reference, ref, margin))
    return table


def with_reference_from(rows: dict[tuple[str, str], dict[int, float | None]],
                        ref_rows: dict[tuple[str, str], dict[int, float | None]],
                        reference: str) -> dict[tuple[str, str], dict[int, float | None]]:
    """``rows`` with the reference controller's runs replaced by its runs in ``ref_rows``
    (another condition's)."""
    out = {k: v for k, v in rows.items() if k[1] != reference}
    out.update({k: v for k, v in ref_rows.items() if k[1] == reference})
    return out


def compare_conditions(base: dict[tuple[str, str], dict[int, float | None]],
                       other: dict[tuple[str, str], dict[int, float | None]],
                       base_name: str, other_name: str,
                       margin: float | None = None) -> list[dict]:
    """Each controller under ``other`` paired by seed against itself under ``base``."""
    return [paired(scenario, f"{c} {other_name}", other[(scenario, c)],
                   f"{c} {base_name}", base[(scenario, c)], margin)
            for scenario, c in sorted(set(base) & set(other))]


def paired(scenario: str, name: str, runs: dict[int, float | None], ref_name: str,
           ref: dict[int, float | None], margin: float | None) -> dict:
    """The row of the table for ``runs`` against ``ref``, paired by seed."""
    seeds = sorted(k for k in runs if k in ref and runs[k] is not None
                   and ref[k] is not None)
    diff = [runs[k] - ref[k] for k in seeds]
    done = [v for v in runs.values() if v is not None]
    ref_done = [v for v in ref.values() if v is not None]
    p = (float(wilcoxon(diff).pvalue) if len(diff) >= 6 and any(diff) else None)
    ci = (tuple(float(v) for v in ttest_1samp(diff, 0.0).confidence_interval(0.95))
          if len(diff) >= 3 and statistics.pstdev(diff) > 0.0 else None)
    p_ni = (float(ttest_1samp(diff, margin, alternative="less").pvalue)
            if margin is not None and ci is not None else None)
    return {
        "scenario": scenario, "controller": name, "reference": ref_name,
        "median": statistics.median(done) if done else None,
        "worst": max(done) if done else None,
        "ref_median": statistics.median(ref_done) if ref_done else None,
        "ref_worst": max(ref_done) if ref_done else None,
        "lost": len(runs) - len(done), "ref_lost": len(ref) - len(ref_done),
        "pairs": len(seeds), "paired_median_diff": statistics.median(diff) if diff
        else None, "better": sum(d < 0 for d in diff), "p": p,
        "mean_diff": statistics.fmean(diff) if diff else None, "mean_diff_ci95": ci,
        "margin": margin, "p_noninferior": p_ni}


def markdown(table: list[dict], metric: str, scale: float, unit: str) -> str:
    def f(v):
        return "—" if v is None else f"{v * scale:.1f}"
    lines = [f"{metric} in {unit}; paired by seed against the reference (Wilcoxon two-sided)",
             "", "| scenario | controller | median (worst) | reference median (worst) | "
             "paired median diff | better on | p | mean diff [95 % CI] |"
             + (" non-inferior at margin |" if table and table[0]["margin"] is not None else ""),
             "|---|---|---|---|---|---|---|---|"
             + ("---|" if table and table[0]["margin"] is not None else "")]
    for r in table:
        p = "—" if r["p"] is None else f"{r['p']:.3f}"
        lost = f", {r['lost']} lost" if r["lost"] else ""
        ref_lost = f", {r['ref_lost']} lost" if r["ref_lost"] else ""
        ci = r["mean_diff_ci95"]
        mean = f(r["mean_diff"]) + ("" if ci is None else f" [{f(ci[0])}, {f(ci[1])}]")
        lines.append(f"| {r['scenario']} | {r['controller']} | {f(r['median'])} "
                     f"({f(r['worst'])}){lost} | {r['reference']} {f(r['ref_median'])} "
                     f"({f(r['ref_worst'])}){ref_lost} | {f(r['paired_median_diff'])} | "
                     f"{r['better']} of {r['pairs']} | {p} | {mean} |"
                     + _noninferior_cell(r, f))
    return "\n".join(lines) + "\n"


def _noninferior_cell(r: dict, f) -> str:
    if r["margin"] is None:
        return ""
    if r["p_noninferior"] is None:
        return " — |"
    verdict = "yes" if r["p_noninferior"] < 0.025 else "not shown"
    return f" {verdict} at {f(r['margin'])} (p {r['p_noninferior']:.3g}) |"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("csv", type=Path)
    ap.add_argument("--reference", default="lqr_ff")
    ap.add_argument("--metric", default="max_abs_lateral_error_m")
    ap.add_argument("--condition", default=None, help="only this condition (default: all rows)")
    ap.add_argument("--margin", type=float, default=None,
                    help="non-inferiority margin in the metric's unit (declared in advance)")
    ap.add_argument("--between", nargs=2, metavar=("BASE", "OTHER"), default=None,
                    help="pair each controller under condition OTHER against itself under "
                    "condition BASE (instead of against --reference)")
    ap.add_argument("--reference-condition", default=None,
                    help="take the reference's runs from this condition (the others' from "
                    "--condition)")
    a = ap.parse_args(argv)
    if not a.csv.is_file():
        print(f"compare_seeds: {a.csv}: no such file", file=sys.stderr)
        return 2
    metres = a.metric.endswith("_m")
    if a.between is not None:
        base, other = (read_rows(a.csv, a.metric, c) for c in a.between)
        table = compare_conditions(base, other, *a.between, a.margin)
        if not table:
            print(f"compare_seeds: no controller ran under both {a.between[0]!r} and "
                  f"{a.between[1]!r}", file=sys.stderr)
            return 2
    else:
        rows = read_rows(a.csv, a.metric, a.condition)
        if a.reference_condition is not None:
            rows = with_reference_from(rows, read_rows(a.csv, a.metric, a.reference_condition),
                                       a.reference)
        table = compare(rows, a.reference, a.margin)
        if not table:
            print(f"compare_seeds: no run of the reference {a.reference!r} beside another "
                  "controller's in the rows selected", file=sys.stderr)
            return 2
    sys.stdout.write(markdown(table, a.metric, 1000.0 if metres else 1.0,
                              "mm" if metres else "its unit"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
