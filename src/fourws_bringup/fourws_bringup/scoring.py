"""Scoring: the content of a run's metrics.json, from its bag (and what the live run knows).

The one module that assembles metrics.json (docs/graph.md, "Runs"). :func:`score_run` reads a
bag (``bag.run_data.read_run``) and combines :func:`bag_metrics` (the tracking metrics of
Tables 6-8 from ``core.metrics`` on the recorded poses and path, plus what the record says
about the run itself: deadline misses, fallbacks, horizon ranges, missing and stray steps,
rejections, step latencies) with the plant's final status and the live outcome. metrics.json
is strict JSON (:func:`metrics_json`). ``fourws run``, ``fourws report``, ``fourws paper``, the
reference bags and the tools all score through here; the in-process loop uses the same
``core.metrics.run_metrics``.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from fourws_common.topics import REFERENCE_TRAJECTORY, VEHICLE_STATE
from fourws_mpc.core.reference import Reference

from .bag.errors import BagError
from .bag.run_data import RunData, read_run
from .core.metrics import reference_from_arrays, run_metrics
from .outputs import output_error
from .runner import RunOutcome

#: a step whose MPC solve took longer than the control period missed its deadline
DEADLINE_MS = 10.0


#: the reason of a bag without the plant's final /run/status (the plant died mid-run)
NO_STATUS = "no /run/status in the bag"
#: what the live run knew of its outcome that such a bag cannot give
LIVE_OUTCOME = ("completed", "reason", "exit_code", "wall_time_s", "scenario", "died",
                "died_error")


def recorded_reference(run: RunData) -> Reference | None:
    """The run's recorded reference path as a ``fourws_mpc`` Reference, or None."""
    r = run.reference
    if not r or len(r.get("x", ())) < 2:
        return None
    return reference_from_arrays(r["x"], r["y"], r["yaw"], r.get("curvature"), r.get("speed"))


def tracking_metrics(run: RunData) -> dict[str, float]:
    """``core.metrics.run_metrics`` of a recorded run: the metrics.json numbers (plus
    ``steps`` and ``sim_time_s``), from the recorded true states (``RunData.truth``),
    reference and solve times.

    Raises :class:`BagError` when the bag holds no state or no reference.
    """
    s = run.truth
    if not len(s["stamp_ns"]):
        raise BagError(f"{run.path}: no {VEHICLE_STATE.name} messages")
    ref = recorded_reference(run)
    if ref is None:
        raise BagError(f"{run.path}: no {REFERENCE_TRAJECTORY.name} message; errors need the "
                       "path")
    solve = run.mpc_diagnostics.get("solve_time_ms")
    return run_metrics(ref, s["t_s"], s["x"], s["y"], s["yaw"], s["vx"], s["vy"],
                       s["sideslip"], solve)


def strict_metrics(metrics: Mapping) -> dict:
    """``metrics`` as strict JSON (RFC 8259) can hold it: every float that is not finite
    (NaN, ±inf: a metric of states that hold NaN, a wall time the bag does not have) becomes
    null, and ``null_reasons`` maps its key path (``step_latency_ms.step.p50``, ``x[2]``) to
    why (``"not finite (nan)"``), so no null in metrics.json is left unexplained."""
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
    """Write ``folder/metrics.json`` (:func:`metrics_json`) whole or not at all (a temporary
    file renamed); a ``RunError`` if it cannot, an ``OutputError`` (exit 1) when the disk is
    full (``outputs.output_error``)."""
    path = folder / "metrics.json"
    tmp = folder / ".metrics.json.tmp"
    try:
        tmp.write_text(metrics_json(metrics), encoding="utf-8")
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
        raise output_error(path, exc) from None
    return path


def scenario_record(scenario: Any) -> dict[str, str]:
    """The scenario file a run was given and the SHA-256 of its content (metrics.json's
    ``scenario_file``, ``scenario_sha256``): the ``scenario`` name is the file's own
    ``name:``, which an edited copy keeps. Empty for a scenario built without a file."""
    source = getattr(scenario, "source", None)
    return {} if source is None else _file_record("scenario", Path(source))


def vehicle_record(vehicle: str) -> dict[str, str]:
    """The car file a run used (a shipped name or a path; empty: the paper's car) and the
    SHA-256 of its content (metrics.json's ``vehicle_file``, ``vehicle_sha256``)."""
    from fourws_common.vehicle_info import vehicle_path

    return _file_record("vehicle", vehicle_path(vehicle or None))


def _file_record(what: str, path: Path) -> dict[str, str]:
    """``{what}_file`` (absolute) and ``{what}_sha256`` of its content."""
    path = path.resolve()
    return {f"{what}_file": str(path),
            f"{what}_sha256": hashlib.sha256(path.read_bytes()).hexdigest()}


def limit_record(run: RunData, metrics: Mapping, lanes: tuple = (),
                 vehicle_width_m: float | None = None) -> dict[str, Any]:
    """The limit metrics (``core.limit_metrics``) of a recorded run, on its true states and
    the commands of the steps that have all three (yaw moment, drive and wheel torques);
    B and R are the recorded controller's allocator's; a metric that does not apply is
    left out. Empty when the bag lacks them."""
    from types import SimpleNamespace

    from .core.configs import load_allocator_config
    from .core.limit_metrics import limit_metrics

    ref = recorded_reference(run)
    s = run.truth
    if ref is None or not len(s["stamp_ns"]):
        return {}
    stamps = np.intersect1d(np.intersect1d(run.mpc_command["stamp_ns"],
                                           run.drive_command["stamp_ns"]),
                            run.wheel_torques["stamp_ns"])

    def at(d: dict, key: str) -> np.ndarray:
        return np.asarray(d[key])[np.searchsorted(d["stamp_ns"], stamps)]

    try:
        cfg = load_allocator_config(str(metrics.get("controller") or run.controller))
    except (ValueError, FileNotFoundError):
        return {}
    log = SimpleNamespace(
        state=s, reference=ref, reason=str(metrics.get("reason", "")),
        completed=bool(metrics.get("completed")), lanes=lanes,
        **({} if vehicle_width_m is None else {"vehicle_width_m": vehicle_width_m}),
        mpc={"yaw_moment": at(run.mpc_command, "yaw_moment")},
        wheel_torque_cmd_nm=at(run.wheel_torques, "torque").reshape(-1, 4),
        drive_torque_nm=at(run.drive_command, "torque"))
    # a metric that does not apply (no cones, no braking) is left out, never NaN
    return {k: v for k, v in limit_metrics(log, cfg.track_width_m, cfg.wheel_radius_m).items()
            if not (isinstance(v, float) and not math.isfinite(v))}


def score_run(path: Path, outcome: RunOutcome | None = None, scenario: str | None = None,
              controller: str | None = None, run: RunData | None = None) -> dict:
    """metrics.json content for a run folder or bag, computed from the bag alone.

    ``outcome`` adds what only the live run knows (wall time, a node that died); ``run``:
    the bag at ``path`` already read (:func:`read_run`), so a caller that also plots it reads
    it once.
    """
    run = read_run(path) if run is None else run
    m = bag_metrics(run)
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
        out["reason"] = str(status.get("reason", NO_STATUS))
        code = status.get("exit_code")
        out["exit_code"] = int(code) if isinstance(code, int) else (
            0 if out["completed"] else None)
    return out


def bag_metrics(run: RunData) -> dict:
    """Table 6-8 metrics (:func:`tracking_metrics`) plus deadline misses, solver fallbacks,
    the horizon ranges, missing and stray steps, rejections and step latencies of a decoded
    bag."""
    m = tracking_metrics(run)
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
    """Where each step's wall time goes, from the messages' wall times (``wall_ns``: the
    publishers' send times; in older bags the recorder's wall receive times, whose own
    delivery delay cancels in each difference up to its jitter): per stage of the
    lockstep chain (state → MPC command → wheel torques → next state), the median and 90th
    percentile in ms over the steps that have both ends. Empty for a bag without them or
    with fewer than two steps."""
    out: dict[str, dict[str, float]] = {}
    for name, src, dst, next_step in LATENCY_STAGES:
        a, b = getattr(run, src), getattr(run, dst)
        if len(a.get("wall_ns", ())) < 2 or len(b.get("wall_ns", ())) < 2:
            continue
        stamps_a = np.asarray(a["stamp_ns"], dtype=np.int64)
        want = stamps_a[1:] if next_step else stamps_a
        start = a["wall_ns"][:-1] if next_step else a["wall_ns"]
        idx = np.searchsorted(b["stamp_ns"], want)
        ok = idx < len(b["stamp_ns"])
        ok[ok] = b["stamp_ns"][idx[ok]] == want[ok]
        d = (b["wall_ns"][idx[ok]] - start[ok]) * 1e-6
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
    if len(run.ground_truth["stamp_ns"]):
        worst = max(worst, int(np.sum(~np.isin(grid, run.ground_truth["stamp_ns"]))))
    # The plant's own count (its final status): states 0..steps, so a recording that began
    # late or ended early is missing steps too, not only one with holes in between.
    steps = (run.status or {}).get("steps")
    if isinstance(steps, int) and (run.status or {}).get("state") == "ended":
        worst = max(worst, steps + 1 - len(stamps))
    return max(worst, 0)


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
