"""Are two ``fourws paper`` outputs the same run? Exit 0 if so, 1 with the differences if not.

    python tools/compare_paper_outputs.py OLD_DIR NEW_DIR

Compares, for every ``CONTROLLER@SCENARIO`` folder of OLD_DIR: every metrics.json value
except the timing ones (wall time, real-time factor, start-up wait, step latencies, solve
times and what depends on them), the table rows and ranking lines of report.md, and every
per-step message of the bags (states, MPC commands, drive commands, wheel torques, decoded
with mcap-ros2-support) for equality. Used to show that a refactor changed no recorded value
(studies/lab-notes/README.md, 2026-12-02).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from mcap_ros2.reader import read_ros2_messages

TIMING = {"wall_time_s", "real_time_factor", "startup_wait_s", "step_latency_ms",
          "mpc_solve_ms_p50", "mpc_solve_ms_p99", "deadline_misses", "null_reasons",
          "late_commands", "overruns", "compose"}
STEP_TOPICS = ("/vehicle/state", "/control/mpc_command", "/control/drive_command",
               "/control/wheel_torques")


def _table_lines(report: Path) -> list[str]:
    lines = report.read_text(encoding="utf-8").splitlines()
    return [ln for ln in lines if (ln.startswith("|") and "fourws" in ln)
            or ln.startswith("Ranking")]


def _messages(mcap: Path) -> list[tuple[str, int, str]]:
    out = [(m.channel.topic, m.publish_time_ns, repr(m.ros_msg))
           for m in read_ros2_messages(str(mcap)) if m.channel.topic in STEP_TOPICS]
    return sorted(out)


def compare(old: Path, new: Path) -> list[str]:
    diffs: list[str] = []
    runs = sorted(p.parent for p in old.glob("*@*/metrics.json"))
    if not runs:
        return [f"{old}: no run folders"]
    for run in runs:
        other = new / run.name
        if not (other / "metrics.json").is_file():
            diffs.append(f"{run.name}: missing in {new}")
            continue
        a = json.loads((run / "metrics.json").read_text(encoding="utf-8"))
        b = json.loads((other / "metrics.json").read_text(encoding="utf-8"))
        for k in sorted((set(a) | set(b)) - TIMING):
            if a.get(k) != b.get(k):
                diffs.append(f"{run.name}: metrics {k}: {a.get(k)!r} != {b.get(k)!r}")
        for f in sorted((run / "bag").glob("*.mcap")):
            g = other / "bag" / f.name
            if not g.is_file():
                diffs.append(f"{run.name}: {g} missing")
            elif _messages(f) != _messages(g):
                diffs.append(f"{run.name}: per-step messages differ")
    if _table_lines(old / "report.md") != _table_lines(new / "report.md"):
        diffs.append("report.md: tables or rankings differ")
    return diffs


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    diffs = compare(Path(argv[0]), Path(argv[1]))
    for d in diffs:
        print(d)
    print("identical" if not diffs else f"{len(diffs)} differences")
    return 1 if diffs else 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
