"""Write ``report.md`` for ``fourws paper``: tables beside the paper's, figures, run facts.

``fourws paper`` and its report are described in docs/bench.md, "Tables 6-8".
"""

from __future__ import annotations

import sys
from pathlib import Path


def _num(v, fmt: str) -> str:
    return format(v, fmt) if isinstance(v, int | float) else ""


def write_report(out: Path, results: dict[tuple[str, str], dict], tables: str,
                 wall_s: float) -> Path:
    """Tables, comparison figures per scenario (overlaying the controllers) and a run table."""
    from .bag.run_data import read_run
    from .report import draw_comparison

    figs: dict[str, list[Path]] = {}
    for scen in sorted({s for _c, s in results}):
        runs = {}
        for (ctrl, s), _m in results.items():
            if s == scen and (out / f"{ctrl}@{s}" / "bag").exists():
                try:
                    runs[ctrl] = read_run(out / f"{ctrl}@{s}")
                except Exception as exc:  # noqa: BLE001 - a bad bag must not stop the report
                    print(f"[report] {ctrl}@{s}: {exc}", file=sys.stderr)
        if runs:
            figs[scen] = draw_comparison(runs, out / "figures" / scen, title=scen)
    lines = [
        "# fourws: the paper's scenarios over ROS 2 topics", "",
        "Every number below is computed from the recorded bag of its run "
        "(`fourws report RUN_DIR` recomputes it). The paper's plant is CarSim; ours is the "
        "fourws_sim two-track model, so the paper's numbers are a reference for order of "
        "magnitude and ranking, not a fit.", "",
        tables, "",
        "## Runs", "",
        "| run | completed | reason | steps | sim time s | wall time s | RTF | start-up wait s "
        "| MPC p50 ms | MPC p99 ms | deadline misses | Np range | Nc range |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (ctrl, scen), m in results.items():
        rtf = m.get("real_time_factor")
        lines.append(
            f"| {ctrl}@{scen} | {m.get('completed')} | {m.get('reason', '')} | "
            f"{m.get('steps', '')} | {m.get('sim_time_s', float('nan')):.2f} | "
            f"{m.get('wall_time_s', float('nan')):.1f} | "
            f"{rtf if rtf is None else f'{rtf:.2f}'} | "
            f"{_num(m.get('startup_wait_s'), '.2f')} | "
            f"{m.get('mpc_solve_ms_p50', float('nan')):.2f} | "
            f"{m.get('mpc_solve_ms_p99', float('nan')):.2f} | {m.get('deadline_misses', '')} | "
            f"{m.get('np_min', '')}..{m.get('np_max', '')} | "
            f"{m.get('nc_min', '')}..{m.get('nc_max', '')} |")
    layouts = sorted({str(m.get("compose", "none")) for m in results.values()})
    lines += ["", f"Total wall time of the {len(results)} runs: {wall_s:.0f} s. Process layout "
              f"(`--compose`): {', '.join(layouts)}; the layout changes the timing only, never "
              "a recorded value.", ""]
    lines += [
        "## Where a step's wall time goes", "",
        "Median (p90) in ms per stage of the lockstep chain, from the recorder's receive "
        "times (`step_latency_ms` in each metrics.json). Each stage holds one node's compute "
        "plus one DDS delivery; `step` is the full period, state to next state.", "",
        "| run | step | state → MPC command | MPC command → wheel torques "
        "| wheel torques → next state | state → drive command |",
        "|---|---|---|---|---|---|",
    ]
    stages = ("step", "state_to_mpc_command", "mpc_command_to_wheel_torques",
              "wheel_torques_to_next_state", "state_to_drive_command")
    for (ctrl, scen), m in results.items():
        lat = m.get("step_latency_ms") or {}
        cells = [f"{lat[k]['p50']:.2f} ({lat[k]['p90']:.2f})" if k in lat else "" for k in stages]
        lines.append(f"| {ctrl}@{scen} | " + " | ".join(cells) + " |")
    lines.append("")
    for scen, paths in figs.items():
        lines += [f"## Figures: {scen}", ""]
        lines += [f"![{p.stem}]({p.relative_to(out).as_posix()})" for p in paths]
        lines.append("")
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
