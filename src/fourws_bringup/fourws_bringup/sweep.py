"""Runs controllers × scenarios × conditions × seeds in the in-process loop, in parallel.

``fourws sweep SPEC.yaml --out DIR [--force] [--workers N | --scheduler ADDRESS]``
(docs/bench.md, "Sweeps"): one CSV row per run and a summary; an existing folder needs
``--force``.

Where one machine is not enough, ``--scheduler tcp://HOST:8786`` runs the same jobs on a
`Dask distributed <https://distributed.dask.org>`_ cluster (``dask scheduler`` on one host,
``dask worker tcp://HOST:8786 --nthreads 1`` on each machine that has fourws installed and
sourced). Dask rather than Ray: it is pure Python and small (no separate runtime or object
store to install beside ROS), a job here is one plain function call with a small picklable
argument and a small dict result, which is exactly ``Client.submit``'s model, and it deploys
on SSH hosts, SLURM/PBS (dask-jobqueue) or Kubernetes without changing this code. Rows are
put back in job order, so the CSV is the same as a local sweep's.

Spec (YAML)::

    controllers: [improved, lqr_ff]          # preset names or YAML paths (beside the spec)
    scenarios: [dlc_60_mu05, dlc_90_mu06]
    seeds: [0, 1, 2, 3, 4]                   # used by conditions with noise; others run once
    conditions:                              # name -> condition (core.conditions)
      ideal: {}
      noise: {noise: {y: {sigma: 0.02, tau_s: 1.0}}}
      all: {noise: {...}, delay_periods: 1, steer_dead_time_ms: 40, tyre_forces: estimated}
      realistic: realistic                   # a shipped condition, by name

Each run is the same core loop as ``run_closed_loop`` (the graph reproduces it); a run that
raises is a row with ``completed`` false and its reason, never a lost run. ``results.csv``
has ``controller, scenario, condition, seed``, every metric key, ``completed``, ``reason``,
the N_p/N_c ranges, the range of each weight and the activity figures of :func:`activity`;
``summary.md`` the median and worst over seeds of max |e_Y|, the aborted count, the median
activity figures, and each controller's margins (``core.margins``) under the condition's
delay and dead time.
"""

from __future__ import annotations

import csv
import json
import math
import os
import sys
import traceback
from collections.abc import Callable, Mapping
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fourws_common.params import read_yaml_file

from .core.conditions import (
    Condition,
    condition_from_mapping,
    condition_mapping,
    node_parameters,
)
from .core.configs import beside

SPEC_KEYS = {"controllers", "scenarios", "seeds", "conditions"}
GROUP_KEYS = {"controllers", "scenarios", "conditions"}
WEIGHTS = ("q_y", "q_phi", "r_ddelta", "r_dmz")
LEAD = ("controller", "scenario", "condition", "seed")


@dataclass(frozen=True)
class Job:
    """One run of the sweep."""

    controller: str
    scenario: str
    condition: Condition

    @property
    def key(self) -> tuple[str, str, str, int]:
        return (self.controller, self.scenario, self.condition.name, self.condition.seed)


def load_spec(path: str | Path) -> list[Job]:
    """The jobs of a spec file, in a fixed order; ``ValueError`` naming a bad key.

    Instead of one product, ``groups: [{controllers, scenarios, conditions}, ...]`` gives
    several (shared ``seeds``); a scenario or controller preset given as a relative ``.yaml``
    path is relative to the spec's folder (``core.configs.beside``)."""
    path = Path(path)
    data = read_yaml_file(path)
    if not isinstance(data, Mapping):
        raise ValueError(f"{path}: a sweep spec is a mapping with {sorted(SPEC_KEYS)}")
    unknown = sorted(set(data) - SPEC_KEYS - {"groups"})
    if unknown:
        raise ValueError(f"{path}: unknown key(s) {unknown} (known: "
                         f"{sorted(SPEC_KEYS | {'groups'})})")
    seeds = data.get("seeds", [0])
    if not isinstance(seeds, list) or not seeds:
        raise ValueError(f"{path}: seeds: a non-empty list of integers, got {seeds!r}")
    groups = data.get("groups") or [{k: data.get(k) for k in GROUP_KEYS}]
    if not isinstance(groups, list):
        raise ValueError(f"{path}: groups: a list of mappings of {sorted(GROUP_KEYS)}")
    jobs: list[Job] = []
    for i, g in enumerate(groups):
        where = f"{path}: groups[{i}]" if "groups" in data else str(path)
        if not isinstance(g, Mapping) or set(g) - GROUP_KEYS:
            raise ValueError(f"{where}: a group has only {sorted(GROUP_KEYS)}")
        for key in sorted(GROUP_KEYS):
            if not g.get(key):
                raise ValueError(f"{where}: '{key}' is missing or empty")
        for key in ("controllers", "scenarios"):
            if not isinstance(g[key], list) or not all(isinstance(v, str) for v in g[key]):
                raise ValueError(f"{where}: {key}: a list of names or files, got {g[key]!r}")
        if not isinstance(g["conditions"], Mapping):
            raise ValueError(f"{where}: conditions: a mapping of names to conditions")
        jobs += _product([beside(path, c) for c in g["controllers"]],
                         [beside(path, s) for s in g["scenarios"]], g["conditions"], seeds,
                         where)
    return jobs


def _product(controllers, scenarios, conditions: Mapping, seeds: list, where: str = ""
             ) -> list[Job]:
    jobs = []
    for name, raw in conditions.items():
        try:                        # every seed checked, whether the condition draws noise
            raw = condition_mapping(raw)
            by_seed = [condition_from_mapping({**raw, "name": str(name)}, seed=seed)
                       for seed in seeds]
        except ValueError as exc:
            raise ValueError(f"{where}: conditions.{name}: {exc}") from None
        noisy = any(s.sigma > 0.0 for s in by_seed[0].noise.values())
        for cond in (by_seed if noisy else by_seed[:1]):
            for c in controllers:
                for s in scenarios:
                    jobs.append(Job(str(c), str(s), cond))
    return jobs


def run_job(job: Job) -> dict[str, Any]:
    """One row: the run's metrics, or its failure.

    The run uses one BLAS thread, whatever the process: a multi-threaded BLAS may sum in
    another order, and a noisy closed loop that is close to chaotic (mpc_4ws under white
    noise) turns a last-bit difference into millimetres, so without the limit a row would
    depend on whether it ran serially, in a pool or on a cluster."""
    from threadpoolctl import threadpool_limits

    from .core.closed_loop import run_closed_loop
    from .core.limit_metrics import limit_metrics

    row: dict[str, Any] = dict(zip(LEAD, job.key, strict=True))
    try:
        with threadpool_limits(limits=1, user_api="blas"):
            log = run_closed_loop(job.scenario, job.controller, condition=job.condition)
        m = log.metrics()
        m.pop("scenario", None)
        m.pop("controller", None)
        row.update(m)
        row["steps"] = log.steps
        row.update(activity(log))
        row.update(limit_metrics(log, *_allocator_geometry(job), nearest=log.nearest))
        for key in ("np", "nc"):
            v = log.mpc[key]
            row[f"{key}_min"], row[f"{key}_max"] = (int(v.min()), int(v.max())) if len(v) else \
                (None, None)
        for w in WEIGHTS:
            v = log.mpc[w]
            row[f"{w}_min"], row[f"{w}_max"] = (float(v.min()), float(v.max())) if len(v) else \
                (None, None)
    except Exception as exc:  # noqa: BLE001 - a failed run is a row, never a lost run
        row["completed"] = False
        row["reason"] = f"{RAISED} {type(exc).__name__}: {exc}"
        row["traceback"] = traceback.format_exc(limit=3)
    return row


#: how :func:`run_job` begins the reason of a run that raised
RAISED = "raised"


def raised(row: Mapping[str, Any]) -> bool:
    """Whether :func:`run_job`'s row is a run that raised (not one that ended early)."""
    return str(row.get("reason", "")).startswith(RAISED)


def _allocator_geometry(job: Job) -> tuple[float, float]:
    """(B, R) of the job's allocator, for the delivered yaw moment and drive force."""
    from .core.configs import load_allocator_config

    cfg = load_allocator_config(job.controller,
                                node_parameters(job.condition)["allocator_node"])
    return cfg.track_width_m, cfg.wheel_radius_m


#: seconds at the end of a run over which :func:`activity` measures the settled yaw rate (the
#: bench scenarios end with a 30 s straight lead-out)
TAIL_S = 10.0


def activity(log: Any) -> dict[str, float]:
    """What max |e_Y| does not show: ``yaw_rate_rms_tail_deg_s``, the RMS of the true yaw
    rate over the last :data:`TAIL_S` s (on a lead-out straight: what is left of the
    manoeuvre plus what the sensor noise keeps exciting), and ``steer_rate_rms_deg_s``, the
    RMS of the front steer command's rate over the run (the control activity)."""
    t, r = log.state["t_s"], log.state["yaw_rate"]
    tail = t >= t[-1] - TAIL_S if len(t) else np.zeros(0, bool)
    d = np.diff(np.asarray(log.mpc["delta_front"], float))
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.01
    return {"yaw_rate_rms_tail_deg_s": math.degrees(float(np.sqrt(np.mean(r[tail] ** 2))))
            if tail.any() else math.nan,
            "steer_rate_rms_deg_s": math.degrees(float(np.sqrt(np.mean(d ** 2))) / dt)
            if len(d) else math.nan}


def run_sweep(jobs: list[Job], workers: int = 1, progress: bool = True,
              scheduler: str | None = None, connect_timeout_s: float = 30.0,
              on_row: Callable[[int, dict[str, Any]], None] | None = None
              ) -> list[dict[str, Any]]:
    """Every job's row, in job order; ``workers`` local processes, or the workers of the
    Dask distributed scheduler at ``scheduler`` (an address such as ``tcp://host:8786``).
    ``on_row(i, row)`` is called as each job's row arrives (the CLI's journal)."""
    rows = _Rows(on_row)
    if scheduler:
        from distributed import Client
        from distributed import as_completed as dask_completed

        with Client(scheduler, timeout=f"{connect_timeout_s}s") as client:
            futures = client.map(run_job, jobs, key=[f"fourws-job-{i}-{_key(j)}"
                                                     for i, j in enumerate(jobs)],
                                 pure=False)
            index = {f.key: i for i, f in enumerate(futures)}
            for fut in dask_completed(futures):
                rows[index[fut.key]] = fut.result()
                _progress(progress, len(rows), len(jobs))
        return [rows[i] for i in range(len(jobs))]
    if workers <= 1:
        for i, job in enumerate(jobs):
            rows[i] = run_job(job)
            _progress(progress, len(rows), len(jobs))
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = {pool.submit(run_job, job): i for i, job in enumerate(jobs)}
            try:
                for fut in as_completed(futures):
                    rows[futures[fut]] = fut.result()
                    _progress(progress, len(rows), len(jobs))
            except BaseException:         # a lost worker, Ctrl-C, a full journal: stop now,
                pool.shutdown(wait=False, cancel_futures=True)   # not after every job
                raise
    return [rows[i] for i in range(len(jobs))]


class _Rows(dict):
    """The rows by job index, each handed to ``on_row`` as it is stored."""

    def __init__(self, on_row: Callable[[int, dict[str, Any]], None] | None) -> None:
        super().__init__()
        self._on_row = on_row

    def __setitem__(self, i: int, row: dict[str, Any]) -> None:
        super().__setitem__(i, row)
        if self._on_row is not None:
            self._on_row(i, row)


def _key(job: Job) -> str:
    return "-".join(str(k) for k in job.key).replace("/", "_")


def _progress(on: bool, done: int, total: int) -> None:
    if on:
        bar = "#" * (30 * done // total) + "." * (30 - 30 * done // total)
        print(f"\r[{bar}] {done}/{total} runs", end="" if done < total else "\n",
              file=sys.stderr, flush=True)


def write_csv(rows: list[dict[str, Any]], path: Path) -> None:
    """results.csv: the lead columns, then every other key in first-seen order."""
    keys: list[str] = list(LEAD)
    for r in rows:
        keys += [k for k in r if k not in keys and k != "traceback"]
    tmp = path.with_name(path.name + ".tmp")    # a full disk never truncates the old file
    try:
        with tmp.open("w", newline="", encoding="utf-8") as f:
            w = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore")
            w.writeheader()
            for r in rows:
                w.writerow({k: _cell(r.get(k)) for k in keys})
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _parse(v: str) -> Any:
    """A results.csv cell back to what :func:`run_job` wrote: bool, float (empty: nan) or
    text."""
    if v in ("True", "False"):
        return v == "True"
    if v == "":
        return math.nan
    try:
        return float(v)
    except ValueError:
        return v


def read_csv(path: Path) -> list[dict[str, Any]]:
    """The rows of a results.csv written by :func:`write_csv`, in job order."""
    with open(path, newline="", encoding="utf-8") as f:
        return [{k: _parse(v) for k, v in r.items()} for r in csv.DictReader(f)]


def _cell(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return ""
    if isinstance(v, dict):
        return repr(v)
    return v


def _median(rows: list[dict[str, Any]], key: str) -> str:
    v = [r[key] for r in rows if isinstance(r.get(key), float) and math.isfinite(r[key])]
    return f"{float(np.median(v)):.3f}" if v else "—"


def summary_markdown(rows: list[dict[str, Any]], jobs: list[Job]) -> str:
    """Median and worst max |e_Y| over seeds, aborted runs, margins, per cell."""
    from fourws_sim.core.scenario import load_scenario

    from .core.configs import load_mpc_config, plant_values
    from .core.margins import margins

    cells: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    conds: dict[str, Condition] = {}
    for job, r in zip(jobs, rows, strict=True):
        cells.setdefault((job.scenario, job.condition.name, job.controller), []).append(r)
        conds[job.condition.name] = job.condition
    lines = ["| scenario | condition | controller | runs | aborted | median max|eY| m | "
             "worst max|eY| m | median yaw-rate RMS, last 10 s, deg/s | median steer-rate "
             "RMS deg/s | ρ | PM deg | DM ms |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for (sc, cond, c), rs in cells.items():
        e = [r["max_abs_lateral_error_m"] for r in rs
             if isinstance(r.get("max_abs_lateral_error_m"), float)
             and math.isfinite(r["max_abs_lateral_error_m"])]
        aborted = sum(1 for r in rs if not r.get("completed"))
        try:
            cnd = conds[cond]
            params = node_parameters(cnd)
            cfg = load_mpc_config(c, params["mpc_node"])
            # the plant as the run had it (a condition's vehicle overrides, e.g. slow steering)
            plant = {**plant_values(), **params["plant_node"]}
            scn = load_scenario(sc, vehicle=plant.get("vehicle_file") or None
                                ).with_vehicle_overrides(plant.get("vehicle_overrides", ""))
            mg = margins(cfg, scn.vehicle, scn.speed_mps, delay_periods=cnd.delay_periods,
                         steer_dead_time_s=cnd.steer_dead_time_s)
            rho, pm, dm = f"{mg.spectral_radius:.4f}", (
                "n/a" if mg.phase_margin_deg is None else f"{mg.phase_margin_deg:.1f}"), (
                "n/a" if mg.delay_margin_ms is None else f"{mg.delay_margin_ms:.1f}")
        except Exception as exc:  # noqa: BLE001 - a margin that cannot be computed is shown
            rho, pm, dm = f"error: {exc}", "", ""
        med = f"{float(np.median(e)):.4f}" if e else "—"
        worst = f"{max(e):.4f}" if e else "—"
        act = [_median(rs, k) for k in ("yaw_rate_rms_tail_deg_s", "steer_rate_rms_deg_s")]
        name = Path(sc).stem if sc.endswith((".yaml", ".yml")) else sc
        lines.append(f"| {name} | {cond} | {c} | {len(rs)} | {aborted} | {med} | {worst} | "
                     f"{act[0]} | {act[1]} | {rho} | {pm} | {dm} |")
    return "\n".join(lines) + "\n"


#: the rows of a sweep as they finish, one JSON object a line, until results.csv is written
JOURNAL = "rows.partial.jsonl"
#: what a sweep writes in its folder (``--force`` replaces only such a folder)
SWEEP_FOLDER_ENTRIES = ("results.csv", "summary.md", JOURNAL, "results.csv.tmp")


def sweep_folder_problem(path: Path) -> str | None:
    """Why ``path`` is not a sweep's output folder (None if it is)."""
    other = sorted(p.name for p in path.iterdir() if p.name not in SWEEP_FOLDER_ENTRIES)
    return f"it holds {other[:5]}" if other else None


def sweep_cli(spec: str, out: str, workers: int, scheduler: str | None = None,
              connect_timeout_s: float = 30.0, force: bool = False) -> int:
    """``fourws sweep``: refuses an existing output folder unless ``force``; each finished
    row goes to :data:`JOURNAL` at once, so an interrupted or failed sweep keeps them."""
    from .outputs import RunError, prepare_out_dir

    try:
        jobs = load_spec(spec)
        out_dir = Path(out)
        prepare_out_dir(out_dir, force, problem=sweep_folder_problem, replace=False,
                        what="fourws sweep folder (" + ", ".join(SWEEP_FOLDER_ENTRIES) + ")")
        out_dir.mkdir(parents=True, exist_ok=True)
        journal = (out_dir / JOURNAL).open("w", encoding="utf-8")
    except (ValueError, OSError, RunError) as exc:
        print(f"fourws sweep: {exc}", file=sys.stderr)
        return 2
    done = 0

    def keep(i: int, row: dict[str, Any]) -> None:
        nonlocal done
        journal.write(json.dumps({"job": i, **row}, default=str) + "\n")
        journal.flush()
        done += 1

    kept = f"the {{}} finished rows of {len(jobs)} are kept in {out_dir / JOURNAL}"

    def failed(text: str, code: int) -> int:
        journal.close()
        if not done:                      # nothing to keep: the folder as it was
            (out_dir / JOURNAL).unlink(missing_ok=True)
            print(f"fourws sweep: {text}", file=sys.stderr)
        else:
            print(f"fourws sweep: {text}; {kept.format(done)}", file=sys.stderr)
        return code

    with journal:
        try:
            rows = run_sweep(jobs, workers, scheduler=scheduler,
                             connect_timeout_s=connect_timeout_s, on_row=keep)
        except KeyboardInterrupt:
            return failed("interrupted", 130)
        except OSError as exc:  # no scheduler at that address, or the journal's disk
            if scheduler and not done:
                return failed(f"scheduler {scheduler}: {exc}", 2)
            return failed(str(exc), 1)
        except Exception as exc:  # noqa: BLE001 - a worker killed: what finished is kept
            return failed(f"{type(exc).__name__}: {exc}", 1)
    try:
        write_csv(rows, out_dir / "results.csv")
        (out_dir / "summary.md").write_text(
            f"# Sweep of {Path(spec).name}: {len(rows)} runs\n\n" + summary_markdown(rows, jobs),
            encoding="utf-8")
    except OSError as exc:
        print(f"fourws sweep: {exc}; {kept.format(done)}", file=sys.stderr)
        return 1
    (out_dir / JOURNAL).unlink(missing_ok=True)
    failed = sum(1 for r in rows if raised(r))
    print(f"{len(rows)} runs, {failed} raised; {out_dir / 'results.csv'}, "
          f"{out_dir / 'summary.md'}")
    return 0
