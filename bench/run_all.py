"""Run every benchmark script in bench/ and merge their JSON into one file.

Usage: python bench/run_all.py OUT.json. Each ``bench_*.py`` takes the path of its own JSON
output as its first argument. Timings are measured here, never asserted in tests.
"""

from __future__ import annotations

import json
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent


def summary_rows(merged: dict) -> list[dict]:
    """Issue 20's table, one row per figure, from the merged results (absent: skipped)."""
    rows: list[dict] = []

    def add(what: str, value: float | None, unit: str, target: str = "", met=None) -> None:
        rows.append({"what": what, "value": value, "unit": unit, "target": target,
                     "met": met})

    for r in merged.get("mpc", {}).get("pairs", []):
        tgt = "p99 <= 0.3" if (r["np"], r["nc"]) == (30, 10) else ""
        met = r["p99_ms"] <= 0.3 if tgt else None
        add(f"MPC step {r['solver']} Np {r['np']} Nc {r['nc']}: median / p99",
            None, f"{r['median_ms']:.3f} / {r['p99_ms']:.3f} ms", tgt, met)
    for r in merged.get("qp", {}).get("pairs", []):
        add(f"QP alone {r['solver']} Np {r['np']} Nc {r['nc']}: median / p99", None,
            f"{r['median_ms']:.3f} / {r['p99_ms']:.3f} ms")
    g = merged.get("graph", {})
    if g.get("in_process_rtf_median"):
        add("in-process RTF (median)", g["in_process_rtf_median"], "")
        targets = {"all": 0.85, "none": 0.6}
        for layout, ratio in g.get("rtf_ratio", {}).items():
            t = targets.get(layout)
            rtfs = [r["real_time_factor"] for r in g["runs"] if r["compose"] == layout]
            add(f"graph RTF --compose {layout} (median {sorted(rtfs)[len(rtfs) // 2]:.2f}) / "
                "in-process", ratio, "", f">= {t}" if t else "",
                (ratio >= t) if t else None)
    sw = merged.get("sweep")
    if sw:
        add(f"sweep throughput ({sw['workers']} workers)", sw["runs_per_minute"], "runs/min")
        add(f"robustness.yaml ({sw['spec_jobs']} runs), projected", sw["projected_spec_minutes"],
            "min", "<= 10", sw["meets_target"])
    return rows


def render(rows: list[dict]) -> list[str]:
    lines = ["", "| figure | value | target | met |", "|---|---|---|---|"]
    for r in rows:
        v = r["unit"] if r["value"] is None else f"{r['value']:.2f} {r['unit']}".strip()
        met = "" if r["met"] is None else ("yes" if r["met"] else "no")
        lines.append(f"| {r['what']} | {v} | {r['target']} | {met} |")
    return lines


def main(out: str) -> int:
    merged: dict = {"machine": {"python": sys.version.split()[0], "cpu": platform.processor()
                                or platform.machine(), "nproc": __import__("os").cpu_count()}}
    failed = []
    for script in sorted(HERE.glob("bench_*.py")):
        with tempfile.NamedTemporaryFile(suffix=".json") as tmp:
            print(f"[bench] {script.name}", flush=True)
            rc = subprocess.call([sys.executable, str(script), tmp.name])
            if rc != 0:
                failed.append(script.name)
                continue
            merged[script.stem.removeprefix("bench_")] = json.loads(Path(tmp.name).read_text())
    merged["table"] = summary_rows(merged)
    Path(out).write_text(json.dumps(merged, indent=2) + "\n")
    print("\n".join(render(merged["table"])))
    print(f"[bench] results in {out}" + (f"; FAILED: {failed}" if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1] if len(sys.argv) > 1 else "bench/results.json"))
