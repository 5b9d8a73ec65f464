"""Reproduce the paper's evidence: runs, metrics from bags, Tables 6-8, report.md.

Every number printed here is computed from a recorded bag by :func:`score_run`, the same code
``fourws report`` uses, so any table can be regenerated from the bags alone.
"""

from __future__ import annotations

import json
import math
import sys
import time
from collections.abc import Mapping
from pathlib import Path

from fourws_common.exit_codes import ExitCode

from .runner import RunError, RunOutcome, prepare_out_dir, run_folder_problem, run_graph

# Paper, Tables 6-8: (max |eY| m, RMSE eY m, MAE eY m, max |eφ| deg, RMSE eφ deg)
PAPER_T6 = {
    "mpc_fws": (0.21414, 0.08966, 0.07075, 3.1302, 0.9826),
    "mpc_4ws": (0.13691, 0.05957, 0.04600, 2.9293, 1.0385),
    "improved": (0.08910, 0.03319, 0.02522, 2.5573, 0.7903),
}
PAPER_T7 = {
    "mpc_fws": (0.37419, 0.17540, 0.14823, 4.8305, 1.8007),
    "mpc_4ws": (0.20706, 0.09896, 0.07935, 5.8284, 2.8856),
    "improved": (0.16297, 0.06216, 0.04721, 3.7547, 1.4459),
}
# Table 8: (max |eY| m, RMSE eY m, MAE eY m, max |β| deg, RMSE β deg)
PAPER_T8 = {
    "ampc_4ws": (0.17071, 0.08657, 0.06701, 1.51226, 0.70869),
    "ampc_4ws_dyc": (0.12377, 0.06416, 0.04892, 0.85826, 0.43511),
    "improved": (0.08907, 0.03318, 0.02500, 0.35506, 0.15139),
}
T67_KEYS = ("max_abs_lateral_error_m", "rmse_lateral_error_m", "mae_lateral_error_m",
            "max_abs_heading_error_deg", "rmse_heading_error_deg")
T8_KEYS = ("max_abs_lateral_error_m", "rmse_lateral_error_m", "mae_lateral_error_m",
           "max_abs_sideslip_deg", "rmse_sideslip_deg")
TABLES = (
    ("Table 6: double lane change, 60 km/h, mu = 0.5", "dlc_60_mu05", PAPER_T6, T67_KEYS,
     ("max|eY| m", "RMSE eY m", "MAE eY m", "max|ephi| deg", "RMSE ephi deg")),
    ("Table 7: double lane change, 90 km/h, mu = 0.6", "dlc_90_mu06", PAPER_T7, T67_KEYS,
     ("max|eY| m", "RMSE eY m", "MAE eY m", "max|ephi| deg", "RMSE ephi deg")),
    ("Table 8: ablation, 60 km/h, mu = 0.5", "dlc_60_mu05", PAPER_T8, T8_KEYS,
     ("max|eY| m", "RMSE eY m", "MAE eY m", "max|beta| deg", "RMSE beta deg")),
)
PAPER_RUNS = [(c, "dlc_60_mu05") for c in ("mpc_fws", "mpc_4ws", "improved", "ampc_4ws",
                                              "ampc_4ws_dyc")] + \
             [(c, "dlc_90_mu06") for c in ("mpc_fws", "mpc_4ws", "improved")]
DEADLINE_MS = 10.0
# Completed runs whose max |eY| differ by less than this fraction of the larger one tie: the
# lockstep runs are deterministic, but an order decided by under 1 % is not a finding.
TIE_REL = 0.01


def run_dir_name(controller: str, scenario: str) -> str:
    return f"{controller}@{Path(scenario).stem}"


def strict_metrics(metrics: Mapping) -> dict:
    """``metrics`` as strict JSON (RFC 8259) can hold it: every float that is not finite
    (NaN, ±inf: a metric of states that hold NaN, a wall time the bag does not have) becomes
    null, and ``null_reasons`` maps its key path (``step_latency_ms.step.p50``, ``x[2]``) to
    why (``"not finite (nan)"``), so no null in metrics.json is left unexplained."""
    import numpy as np

    reasons: dict[str, str] = dict(metrics.get("null_reasons") or {})

    def clean(v, path: str):
        if isinstance(v, Mapping):
            return {k: clean(x, f"{path}.{k}" if path else str(k)) for k, x in v.items()
                    if not (k == "null_reasons" and not path)}
        if isinstance(v, list | tuple | np.ndarray):
            return [clean(x, f"{path}[{i}]") for i, x in enumerate(v)]
        if isinstance(v, np.generic):
            v = v.item()
        if isinstance(v, float) and not math.isfinite(v):
            reasons[path] = f"not finite ({v})"
            return None
        return v

    out = clean(metrics, "")
    if reasons:
        out["null_reasons"] = reasons
    return out


def metrics_json(metrics: Mapping) -> str:
    """The text of metrics.json: :func:`strict_metrics`, indented, no NaN or Infinity."""
    return json.dumps(strict_metrics(metrics), indent=2, allow_nan=False) + "\n"


def write_metrics(folder: Path, metrics: Mapping) -> Path:
    """Write ``folder/metrics.json`` (:func:`metrics_json`); a ``RunError`` if it cannot."""
    path = folder / "metrics.json"
    try:
        path.write_text(metrics_json(metrics), encoding="utf-8")
    except OSError as exc:
        raise RunError(f"cannot write {path}: {exc.strerror or exc}") from None
    return path


def score_run(path: Path, outcome: RunOutcome | None = None, scenario: str | None = None,
              controller: str | None = None) -> dict:
    """metrics.json content for a run folder or bag, computed from the bag alone.

    ``outcome`` adds what only the live run knows (wall time, a node that died).
    """
    from .bag import read_run

    run = read_run(path)
    m = metrics_from_run(run)
    # The plant's final status: from its status file (outcome) when the live run has one,
    # else as recorded in the bag.
    recorded = run.status if (run.status or {}).get("state") == "ended" else None
    status = (outcome.status if outcome is not None and outcome.status else None) \
        or recorded or {}
    scenario = scenario or status.get("scenario") or "unknown"
    controller = controller or (run.controller or "unknown")
    out = {"scenario": Path(scenario).stem, "controller": controller}
    out["steps"] = int(m.pop("steps"))
    out["sim_time_s"] = float(m.pop("sim_time_s"))
    # The plant's own span from its first answered state to the end (in the bag; the wait
    # before it, nodes discovering each other, is startup_wait_s); the runner's clock only
    # when the bag has none (a plant that died).
    wall = status.get("wall_time_s")
    if not isinstance(wall, int | float) or not wall > 0:
        wall = outcome.wall_time_s if outcome else float("nan")
    out["wall_time_s"] = wall
    out["real_time_factor"] = out["sim_time_s"] / wall if wall and wall == wall else None
    startup = status.get("startup_wait_s")
    out["startup_wait_s"] = float(startup) if isinstance(startup, int | float) else None
    out.update(m)
    for key in ("late_commands", "safe_hold_steps", "overruns", "rejected_commands"):
        if isinstance(status.get(key), int):
            out[key] = status[key]
    if outcome is not None and (outcome.status or outcome.died or not recorded):
        out["completed"] = bool(outcome.completed)
        out["reason"] = outcome.reason
        if outcome.died:
            out["died"] = outcome.died
            out["died_error"] = outcome.died_error
        out["exit_code"] = int(outcome.code)
    else:
        out["completed"] = bool(status.get("completed", False))
        out["reason"] = str(status.get("reason", "no /run/status in the bag"))
        code = status.get("exit_code")
        out["exit_code"] = int(code) if isinstance(code, int) else (
            0 if out["completed"] else None)
    return out


def metrics_from_run(run) -> dict:
    """Table 6-8 metrics (:func:`fourws_bringup.report.metrics_from_run`) plus deadline
    misses, solver fallbacks and the horizon ranges of a decoded bag."""
    import numpy as np

    from .report import metrics_from_run as core_metrics

    m = core_metrics(run)
    m["steps"] = max(run.steps - 1, 0)  # control steps: the last state gets no command
    diag = run.mpc_diagnostics
    solve = np.asarray(diag.get("solve_time_ms", np.zeros(0)), dtype=float)
    m["deadline_misses"] = int(np.sum(solve > DEADLINE_MS))
    for key in ("np", "nc"):
        v = diag.get(key)
        if v is not None and len(v):
            m[f"{key}_min"], m[f"{key}_max"] = int(np.min(v)), int(np.max(v))
    fb = diag.get("fallback")
    m["mpc_fallbacks"] = int(np.sum(fb)) if fb is not None else 0
    m["missing_steps"] = missing_steps(run)
    m["stray_messages"] = dict(getattr(run, "strays", {}))  # off the timeline, not scored
    # What each node rejected (inputs, stamps, caught errors), from /diagnostics; only the
    # nodes that rejected something. Absent from bags recorded before /diagnostics existed.
    m["input_rejections"] = {n: {k: v for k, v in c.items() if v}
                             for n, c in sorted(getattr(run, "rejections", {}).items())
                             if any(c.values())}
    lat = step_latencies_ms(run)
    if lat:
        m["step_latency_ms"] = lat
    return m


LATENCY_STAGES = (
    # name, from topic, to topic, to the next step's stamp
    ("state_to_mpc_command", "state", "mpc_command", False),
    ("state_to_drive_command", "state", "drive_command", False),
    ("mpc_command_to_wheel_torques", "mpc_command", "wheel_torques", False),
    ("wheel_torques_to_next_state", "wheel_torques", "state", True),
    ("step", "state", "state", True),
)


def step_latencies_ms(run) -> dict[str, dict[str, float]]:
    """Where each step's wall time goes, from the recorder's receive times (``log_ns``):
    per stage of the lockstep chain (state → MPC command → wheel torques → next state), the
    median and 90th percentile in ms over the steps that have both ends. The recorder's own
    delivery delay cancels in each difference up to its jitter. Empty for a bag without
    receive times or with fewer than two steps."""
    import numpy as np

    out: dict[str, dict[str, float]] = {}
    for name, src, dst, next_step in LATENCY_STAGES:
        a, b = getattr(run, src), getattr(run, dst)
        if len(a.get("log_ns", ())) < 2 or len(b.get("log_ns", ())) < 2:
            continue
        stamps_a = np.asarray(a["stamp_ns"], dtype=np.int64)
        want = stamps_a[1:] if next_step else stamps_a
        start = a["log_ns"][:-1] if next_step else a["log_ns"]
        idx = np.searchsorted(b["stamp_ns"], want)
        ok = idx < len(b["stamp_ns"])
        ok[ok] = b["stamp_ns"][idx[ok]] == want[ok]
        d = (b["log_ns"][idx[ok]] - start[ok]) * 1e-6
        if len(d):
            out[name] = {"p50": float(np.median(d)), "p90": float(np.percentile(d, 90))}
    return out


def missing_steps(run) -> int:
    """Step stamps absent from the bag: on the state's period grid between its first and
    last stamp, the largest count missing from any per-step topic, and at least the states
    the plant's final status counts but the bag lacks (0 for a complete record).

    A recorder that fell behind its subscriptions' queues loses messages without an error;
    this finds the gap from the data alone, for any bag (also recovered ones).
    """
    import numpy as np

    stamps = np.asarray(run.state["stamp_ns"], dtype=np.int64)
    if len(stamps) < 2:
        return 0
    period = int(np.median(np.diff(stamps)))
    if period <= 0:
        return 0
    grid = stamps[0] + period * np.arange(int(round((stamps[-1] - stamps[0]) / period)) + 1)
    worst = int(np.sum(~np.isin(grid, stamps)))
    # Commands exist for every state but the last (its answer may still be in flight).
    for topic in (run.mpc_command, run.mpc_diagnostics, run.drive_command, run.wheel_torques):
        if len(topic["stamp_ns"]):
            worst = max(worst, int(np.sum(~np.isin(grid[:-1], topic["stamp_ns"]))))
    # The plant's own count (its final status): states 0..steps, so a recording that began
    # late or ended early is missing steps too, not only one with holes in between.
    steps = (run.status or {}).get("steps")
    if isinstance(steps, int) and (run.status or {}).get("state") == "ended":
        worst = max(worst, steps + 1 - len(stamps))
    return max(worst, 0)


def run_and_score(scenario: str, controller: str, out_dir: Path, *, force: bool = False,
                  mode: str = "lockstep", plots: bool = True, progress: bool = True,
                  compose: str = "none") -> dict:
    """``fourws run``: one run over topics, then metrics.json and plots from its bag.

    ``compose``: the process layout (:func:`fourws_bringup.runner.graph_specs`), recorded in
    metrics.json; it changes the timing only, never a recorded value.
    """
    from fourws_sim.core.scenario import load_scenario

    from .runner import controller_preset

    controller_preset(controller)
    try:
        sc = load_scenario(scenario)
    except (ValueError, FileNotFoundError) as exc:
        why = str(exc).removeprefix(f"{Path(scenario)}: ")  # the file is named once
        raise RunError(f"scenario '{scenario}': {why}") from exc
    prepare_out_dir(out_dir, force)
    print(f"[fourws] {controller} on {sc.name}: {sc.summary()}", file=sys.stderr)
    outcome = run_graph(scenario, controller, out_dir, mode=mode, progress=progress,
                        compose=compose)
    try:
        metrics = score_run(out_dir, outcome, scenario=sc.name, controller=controller)
    except Exception as exc:  # noqa: BLE001 - the run's own record must still be written
        metrics = {"scenario": sc.name, "controller": controller, "completed": False,
                   "reason": f"{outcome.reason}; metrics failed: {exc}",
                   "wall_time_s": outcome.wall_time_s, "exit_code": int(ExitCode.ERROR)}
        if outcome.died:
            metrics["died"] = outcome.died
            metrics["died_error"] = outcome.died_error
    metrics["compose"] = compose
    write_metrics(out_dir, metrics)
    if plots and (out_dir / "bag").exists():
        try:
            from .bag import read_run
            from .report import draw_figures

            draw_figures(read_run(out_dir), out_dir / "plots")
        except Exception as exc:  # noqa: BLE001
            print(f"[fourws] figures failed: {exc}", file=sys.stderr)
    return metrics


def report_path(path: Path, out: Path | None = None) -> dict:
    """``fourws report``: metrics.json and figures recomputed from a bag or run folder.

    A ``RunError`` (before the bag is read) when ``out`` cannot be written.
    """
    from .bag import read_run
    from .report import draw_figures
    from .runner import writable_dir

    if not path.exists():
        raise FileNotFoundError(f"{path}: no such bag or run folder")
    out = out or (path if (path / "bag").is_dir() else path.parent)
    writable_dir(out)
    metrics = score_run(path)
    write_metrics(out, metrics)
    draw_figures(read_run(path), out / "plots")
    return metrics


def _fmt(v) -> str:
    return f"{v:.5f}" if isinstance(v, float) else str(v)


def rank(metrics: dict[str, dict], key: str) -> list[str]:
    """Controllers best first on ``key``: runs that completed the manoeuvre rank by the
    metric, ahead of every run that aborted (left the road or spun), which rank by how long
    they lasted. An aborted run's error statistics cover only part of the path."""
    def order(c: str):
        m = metrics[c]
        done = bool(m.get("completed"))
        return (0, m[key]) if done else (1, -float(m.get("sim_time_s", 0.0)), m[key])
    return sorted(metrics, key=order)


def tie_groups(metrics: dict[str, dict], order: list[str], key: str) -> list[list[str]]:
    """``order`` (from :func:`rank`) cut into groups of consecutive completed runs whose
    ``key`` lies within ``TIE_REL`` of the group's first; aborted runs stay alone."""
    groups: list[list[str]] = []
    for c in order:
        m = metrics[c]
        if groups and m.get("completed") and metrics[groups[-1][0]].get("completed"):
            v0, v = metrics[groups[-1][0]][key], m[key]
            if abs(v - v0) <= TIE_REL * max(abs(v), abs(v0)):
                groups[-1].append(c)
                continue
        groups.append([c])
    return groups


def consistent(groups: list[list[str]], order: list[str]) -> bool:
    """Whether ``order`` is one of the orders the tie groups allow."""
    pos = {c: i for i, g in enumerate(groups) for c in g}
    idx = [pos.get(c, -1) for c in order]
    return -1 not in idx and idx == sorted(idx)


def format_tables(results: dict[tuple[str, str], dict]) -> str:
    """The three tables, ours beside the paper's, as Markdown."""
    lines = []
    for title, scenario, paper, keys, heads in TABLES:
        lines += [f"### {title}", "",
                  "| controller | source | " + " | ".join(heads) + " |",
                  "|---|---|" + "---|" * len(heads)]
        for ctrl, ref in paper.items():
            m = results.get((ctrl, scenario))
            ours = [_fmt(m.get(k)) if m else "not run" for k in keys]
            if m and not m.get("completed"):
                ours[0] += f" (aborted at {m.get('sim_time_s', 0.0):.1f} s)"
            lines.append(f"| {ctrl} | fourws | " + " | ".join(ours) + " |")
            lines.append(f"| {ctrl} | paper | " + " | ".join(f"{v:.5f}" for v in ref) + " |")
        ours_m = {c: results[(c, scenario)] for c in paper if (c, scenario) in results}
        order = rank(ours_m, "max_abs_lateral_error_m")
        paper_order = sorted(paper, key=lambda c: paper[c][0])
        verdict = "same" if order == paper_order else "DIFFERENT"
        groups = tie_groups(ours_m, order, "max_abs_lateral_error_m")
        ours_text = " < ".join(" ≈ ".join(g) for g in groups)
        if verdict != "same" and consistent(groups, paper_order):
            ties = "; ".join(" ≈ ".join(g) for g in groups if len(g) > 1)
            verdict = f"same up to a tie within {TIE_REL:.0%}: {ties}"
        lines += ["", f"Ranking on max |eY| (best first): fourws {ours_text}; "
                      f"paper {' < '.join(paper_order)} ({verdict})", ""]
    return "\n".join(lines)


def allocation_note(out: Path, results: dict[tuple[str, str], dict]) -> str:
    """A paragraph on Table 8's allocation step from the bag of ``improved@dlc_60_mu05``
    under ``out`` (``report.allocation_audit`` against rule-based allocation); empty when
    that run is not among ``results``; says why when its bag cannot be audited."""
    from .bag import BagError, read_run
    from .report import allocation_audit

    key = ("improved", "dlc_60_mu05")
    if key not in results:
        return ""
    name = run_dir_name(*key)
    try:
        a = allocation_audit(read_run(out / name), other="rule")
    except (BagError, ValueError) as exc:
        return f"Allocation audit of {name}: not available ({exc})."
    return (
        f"Allocation audit of {name} (its bag; `python tools/allocation_audit.py`): on the "
        f"same recorded demands and wheel loads, rule-based allocation would change no wheel "
        f"torque by more than {a['max_difference_nm']:.1f} N·m (median "
        f"{a['median_difference_nm']:.1f} N·m). Eq. (27) fixes each side's torque sum, so "
        f"eq. (26)-(31) only splits it between front and rear: the rear wheel gets "
        f"{100 * a['rear_share_min']:.1f}-{100 * a['rear_share_max']:.1f} % (rule: 50 %). "
        f"|Mz| ≤ {a['max_abs_yaw_moment_nm']:.0f} N·m; the busiest tyre uses "
        f"{100 * a['max_tyre_usage']:.0f} % of its friction (eq. 25). The recorded wheel "
        f"torques are the allocator core's output on the recorded inputs to "
        f"{a['replay_error_nm']:.1e} N·m.")


def run_paper(out: Path, *, force: bool = False, only: list[str] | None = None,
              compose: str = "none") -> int:
    """``fourws paper``: the eight runs, the tables beside the paper's, report.md.

    ``force`` lets an existing output of ``fourws paper`` (:func:`paper_folder_problem`) be
    written over: each run's folder is replaced, report.md and figures/ rewritten, other run
    folders kept. Any other non-empty folder is refused.
    """
    prepare_out_dir(out, force, problem=paper_folder_problem, replace=False,
                    what="fourws paper output (" + ", ".join(PAPER_FOLDER_ENTRIES)
                    + ", CONTROLLER@SCENARIO/ run folders)")
    runs = PAPER_RUNS
    if only:
        runs = [r for r in runs if f"{r[0]}@{r[1]}" in only]
    results: dict[tuple[str, str], dict] = {}
    t_start = time.monotonic()
    for i, (ctrl, scen) in enumerate(runs):
        bar = "#" * i + "." * (len(runs) - i)
        print(f"[{bar}] run {i + 1}/{len(runs)}: {ctrl} on {scen}", file=sys.stderr)
        m = run_and_score(scen, ctrl, out / run_dir_name(ctrl, scen), force=True,
                          compose=compose)
        results[(ctrl, scen)] = m
        step_ms = (m.get("step_latency_ms") or {}).get("step", {}).get("p50", float("nan"))
        print(f"    max|eY| {m.get('max_abs_lateral_error_m', float('nan')):.4f} m, "
              f"RTF {m.get('real_time_factor') or float('nan'):.2f} "
              f"(step {step_ms:.2f} ms median), "
              f"{'completed' if m.get('completed') else 'NOT completed: ' + m.get('reason', '')}",
              file=sys.stderr)
    wall = time.monotonic() - t_start
    tables = format_tables(results)
    note = allocation_note(out, results)
    if note:
        tables += "\n" + note + "\n"
    print(tables)
    print(f"\n{len(runs)} runs in {wall:.0f} s of wall time")
    from .report_md import write_report

    write_report(out, results, tables, wall)
    print(f"report: {out / 'report.md'}")
    failed = {f"{c}@{s}": why for (c, s), m in results.items() if (why := run_failure(m))}
    for name, why in failed.items():
        print(f"fourws paper: {name} failed: {why}", file=sys.stderr)
    return 1 if failed else 0


#: What ``fourws paper`` writes beside its run folders (``CONTROLLER@SCENARIO/``).
PAPER_FOLDER_ENTRIES = ("report.md", "figures")


def paper_folder_problem(folder: Path) -> str | None:
    """Why ``folder`` is not the output of ``fourws paper``, or None if it is: it holds only
    report.md, figures/ and run folders named ``CONTROLLER@SCENARIO``
    (:func:`fourws_bringup.runner.run_folder_problem`), at least one of them."""
    entries = sorted(folder.iterdir())
    other = [p.name for p in entries if p.name not in PAPER_FOLDER_ENTRIES
             and not (p.is_dir() and "@" in p.name)]
    if other:
        more = f" and {len(other) - 5} more" if len(other) > 5 else ""
        return f"it holds {', '.join(repr(n) for n in other[:5])}{more}"
    for p in entries:
        if p.name in PAPER_FOLDER_ENTRIES or not any(p.iterdir()):
            continue  # an empty run folder: one that was about to start
        if (why := run_folder_problem(p)) is not None:
            return f"{p.name}/ is not a run folder: {why}"
    if not any(p.name == "report.md" or "@" in p.name for p in entries):
        return "it has no report.md and no run folder"
    return None


def run_failure(m: dict) -> str | None:
    """Why a run gives no trustworthy result, or None. A run the scenario aborted (the car
    left the ±5 m corridor, as MPC-FWS does on this plant) is a result, not a failure; a node
    that died, metrics that could not be computed, or steps missing from the bag are."""
    if m.get("died"):
        return f"node {m['died']} died"
    if "steps" not in m:
        return m.get("reason", "no metrics")
    if m.get("missing_steps"):
        return f"{m['missing_steps']} steps missing from the bag"
    return None
