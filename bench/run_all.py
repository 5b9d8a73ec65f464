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
#: where ``make test`` leaves the time of its pytest session (tests/conftest.py)
ROOT_RUNS = HERE.parent / "runs"


#: the speed targets (issue "Speed"): figure -> (target text, test on the value)
TARGETS = {
    "mpc_np30": ("p99 <= 0.3 ms", lambda v: v <= 0.3),
    "mpc_np12": ("p99 <= 0.2 ms", lambda v: v <= 0.2),
    "plant": ("median <= 0.03 ms", lambda v: v <= 0.03),
    "in_process_rtf": (">= 30", lambda v: v >= 30.0),
    "graph_rtf_all": (">= 10", lambda v: v >= 10.0),
    "run_end_to_end": ("<= 4 s", lambda v: v <= 4.0),
    "robustness": ("<= 10 min", lambda v: v <= 10.0),
    "make_test": ("<= 8 min", lambda v: v <= 8.0),
}


def summary_rows(merged: dict) -> list[dict]:
    """One row per figure, with its target where it has one (absent: skipped)."""
    rows: list[dict] = []

    def add(what: str, value: float | None, unit: str, key: str = "", shown: str = "") -> None:
        target, ok = TARGETS.get(key, ("", None))
        rows.append({"what": what, "value": value, "unit": unit, "shown": shown,
                     "target": target,
                     "met": None if ok is None or value is None else bool(ok(value))})

    for r in merged.get("mpc", {}).get("pairs", []):
        key = {(30, 10): "mpc_np30", (12, 6): "mpc_np12"}.get((r["np"], r["nc"]), "")
        add(f"MPC step {r['solver']} Np {r['np']} Nc {r['nc']}: median / p99",
            r["p99_ms"] if r["solver"] == "daqp" else None, "ms",
            key if r["solver"] == "daqp" else "",
            f"{r['median_ms']:.3f} / {r['p99_ms']:.3f} ms")
    for r in merged.get("qp", {}).get("pairs", []):
        add(f"QP alone {r['solver']} Np {r['np']} Nc {r['nc']}: median / p99", None, "",
            shown=f"{r['median_ms']:.3f} / {r['p99_ms']:.3f} ms")
    sim = merged.get("sim", {})
    if sim:
        add("plant 10 ms step (RK4, outputs included): median / p99", sim["median_ms"], "ms",
            "plant", f"{sim['median_ms']:.4f} / {sim['p99_ms']:.4f} ms")
    g = merged.get("graph", {})
    if g.get("in_process_rtf_median"):
        add("in-process RTF (median)", g["in_process_rtf_median"], "", "in_process_rtf")
        for layout in g.get("rtf_ratio", {}):
            rtfs = sorted(r["real_time_factor"] for r in g["runs"] if r["compose"] == layout)
            add(f"graph RTF, lockstep, --compose {layout} (median)", rtfs[len(rtfs) // 2], "",
                "graph_rtf_all" if layout == "all" else "")
    if g.get("end_to_end"):
        walls = sorted(r["wall_s"] for r in g["end_to_end"])
        add("`fourws run` dlc_60_mu05 improved, end to end (median)", walls[len(walls) // 2],
            "s", "run_end_to_end")
    sw = merged.get("sweep")
    if sw:
        add(f"sweep throughput ({sw['workers']} workers)", sw["runs_per_minute"], "runs/min")
        add(f"robustness bench ({sw['spec_jobs']} runs, {sw['workers']} workers), projected",
            sw["projected_spec_minutes"], "min", "robustness")
    t = merged.get("make_test")
    if t:
        add(f"`make test` pytest session ({t['tests']} tests, last run {t['finished']})",
            t["minutes"], "min", "make_test")
    return rows


def render(rows: list[dict]) -> list[str]:
    lines = ["", "| figure | value | target | met |", "|---|---|---|---|"]
    for r in rows:
        v = r["shown"] or (f"{r['value']:.2f} {r['unit']}".strip() if r["value"] is not None
                           else "")
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
    last_test = ROOT_RUNS / "make-test.json"
    if last_test.is_file():
        merged["make_test"] = json.loads(last_test.read_text())
    merged["table"] = summary_rows(merged)
    Path(out).write_text(json.dumps(merged, indent=2) + "\n")
    print("\n".join(render(merged["table"])))
    print(f"[bench] results in {out}" + (f"; FAILED: {failed}" if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1] if len(sys.argv) > 1 else "bench/results.json"))
