"""Figures and Markdown pieces of a run report, from recorded runs (:class:`bag.run_data.RunData`).

Figures (matplotlib, Agg, PNG; docs/graph.md, "Runs"), as in the paper:

- Figures 5 and 7: (a) trajectory against the reference, (b) lateral error, (c) heading error,
  (d) heading with the reference heading, (e) sideslip angle, (f) yaw rate; one PNG each and
  ``overview.png`` with the six panels.
- Figure 6: (a) horizons Np, Nc; (b) weight ratios ``q_y/Q_y,max``, ``q_phi/Q_phi,max``,
  ``r_ddelta/R_ddelta,max``, ``r_dmz/R_dMz,max`` with the maxima of eq. (23)
  (8000, 5000, 80000, 60000 by default).
- The four in-wheel motor torque commands with the yaw-moment demand Mz.

Lateral and heading errors are recomputed from the recorded poses against the recorded
``/reference/trajectory`` with the metrics' own projection (``core.metrics``), so the plotted
errors are the numbers in metrics.json; without a reference the MPC's own diagnostics are
plotted instead. Angles are shown in degrees, everything else in SI units.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fourws_common.topics import DRIVE_COMMAND, MPC_COMMAND, VEHICLE_STATE, WHEEL_TORQUES
from fourws_common.wheels import Wheel

from .bag.errors import BagError
from .bag.run_data import RunData
from .scoring import recorded_reference

WHEELS = tuple(w.name for w in Wheel)  # FL FR RL RR
PAPER_WEIGHT_MAXIMA = {"q_y": 8000.0, "q_phi": 5000.0, "r_ddelta": 80000.0, "r_dmz": 60000.0}


# ---------------------------------------------------------------------------------------------
# Quantities
# ---------------------------------------------------------------------------------------------
@dataclass
class Series:
    """What the figures show of one run (SI, radians)."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    sideslip: np.ndarray
    yaw_rate: np.ndarray
    lateral_error: np.ndarray
    heading_error: np.ndarray
    ref_heading: np.ndarray | None
    ref_xy: tuple[np.ndarray, np.ndarray] | None
    diagnostics: Mapping[str, np.ndarray]
    torque_t: np.ndarray
    torque: np.ndarray
    mz_t: np.ndarray
    mz: np.ndarray


def series_of(run: RunData) -> Series:
    """Per-step quantities of a run for plotting (errors as the metrics compute them)."""
    s = run.state
    if not len(s["stamp_ns"]):
        raise BagError(f"{run.path}: no /vehicle/state messages; nothing to plot")
    ref = recorded_reference(run)
    yaw = np.unwrap(s["yaw"])
    if ref is not None:
        n = len(s["x"])
        e_y, e_phi = np.empty(n), np.empty(n)
        hint = None
        for k in range(n):
            e = ref.errors(float(s["x"][k]), float(s["y"][k]), float(s["yaw"][k]), hint)
            hint = e.near.index
            e_y[k], e_phi[k] = e.lateral_error, e.heading_error
        ref_xy = (np.asarray(ref.x), np.asarray(ref.y))
        ref_heading = yaw - e_phi  # the path heading on the vehicle's branch of the angle
    else:
        d = run.mpc_diagnostics
        idx = _align(d.get("stamp_ns"), s["stamp_ns"])
        e_y = _take(d.get("lateral_error"), idx)
        e_phi = _take(d.get("heading_error"), idx)
        ref_xy, ref_heading = None, None
    w = run.wheel_torques
    if len(w.get("stamp_ns", ())) and "torque" in w:
        torque_t, torque = w["t_s"], np.asarray(w["torque"], float).reshape(-1, 4)
    else:
        torque_t, torque = s["t_s"], np.asarray(s["wheel_torque"], float).reshape(-1, 4)
    c = run.mpc_command
    mz_t = c["t_s"] if "yaw_moment" in c else np.zeros(0)
    mz = c["yaw_moment"] if "yaw_moment" in c else np.zeros(0)
    return Series(s["t_s"], s["x"], s["y"], yaw, s["sideslip"], s["yaw_rate"], e_y, e_phi,
                  ref_heading, ref_xy, run.mpc_diagnostics, torque_t, torque, mz_t, mz)


def allocation_audit(run: RunData, other: str = "rule", cfg=None) -> dict[str, Any]:
    """The lower layer of a recorded run, re-run from the bag (``core.metrics``).

    For every stamp with a state, a drive command, an MPC command and wheel torques:
    ``replay_error_nm`` is the largest |recorded − recomputed| wheel torque with the recorded
    method (that of the last step; 0 when the allocator did what its core says, > 0 where it
    held its last output after rejecting an input or its method was changed mid-run);
    ``max``/``median_difference_nm`` compare it with method ``other`` (largest per-wheel |ΔT|
    per step); ``rear_share_min``/``_max`` bound the load-ratio share of eq. (26)-(31);
    ``max_tyre_usage`` is the largest η of eq. (25) from the recorded tyre forces;
    ``max_abs_yaw_moment_nm`` the largest |M_z|.
    ``cfg`` (geometry and limits; the method is the recorded one) defaults to the package's
    ``allocator.yaml``. Raises :class:`BagError` when the bag lacks a topic the audit needs.
    """
    from .core.configs import load_allocator_config
    from .core.metrics import allocate_series, rear_load_ratio_share, tyre_usage

    cfg = cfg or load_allocator_config(None)
    s, d, c, w = run.state, run.drive_command, run.mpc_command, run.wheel_torques
    for topic, cols, key in ((VEHICLE_STATE.name, s, "fz"), (DRIVE_COMMAND.name, d, "torque"),
                             (MPC_COMMAND.name, c, "yaw_moment"),
                             (WHEEL_TORQUES.name, w, "torque"),
                             (WHEEL_TORQUES.name, w, "allocation")):
        if not len(cols.get("stamp_ns", ())) or key not in cols:
            raise BagError(f"{run.path}: no {topic} messages; the allocation audit needs them")
    stamps = w["stamp_ns"]
    idx = {name: _align(cols["stamp_ns"], stamps) for name, cols in (("s", s), ("d", d),
                                                                     ("c", c))}
    ok = (idx["s"] >= 0) & (idx["d"] >= 0) & (idx["c"] >= 0)
    if not ok.any():
        raise BagError(f"{run.path}: no step has all four allocation topics")
    i_s, i_d, i_c = (idx[k][ok] for k in ("s", "d", "c"))
    fz, fy, mu = (np.asarray(s[k], float).reshape(-1, 4)[i_s] for k in ("fz", "fy", "mu"))
    t, mz = np.asarray(d["torque"], float)[i_d], np.asarray(c["yaw_moment"], float)[i_c]
    method = str(w["allocation"][ok][-1])
    recorded = np.asarray(w["torque"], float).reshape(-1, 4)[ok]
    mine = allocate_series(method, t, mz, fz, fy, mu, cfg)
    theirs = allocate_series(other, t, mz, fz, fy, mu, cfg)
    diff = np.abs(mine - theirs).max(axis=1)
    share = rear_load_ratio_share(fz, mu)
    eta = tyre_usage(s["fx"], s["fy"], s["fz"], s["mu"])
    eta = eta[np.isfinite(eta)]
    return {
        "method": method, "other": other, "steps": int(ok.sum()),
        "replay_error_nm": float(np.abs(recorded - mine).max()),
        "max_difference_nm": float(diff.max()),
        "median_difference_nm": float(np.median(diff)),
        "rear_share_min": float(np.nanmin(share)), "rear_share_max": float(np.nanmax(share)),
        "max_tyre_usage": float(eta.max()) if eta.size else math.nan,
        "max_abs_yaw_moment_nm": float(np.abs(mz).max()),
    }


def _align(src_stamps: np.ndarray | None, dst_stamps: np.ndarray) -> np.ndarray | None:
    if src_stamps is None or not len(src_stamps):
        return None
    idx = np.searchsorted(src_stamps, dst_stamps)
    idx = np.clip(idx, 0, len(src_stamps) - 1)
    return np.where(src_stamps[idx] == dst_stamps, idx, -1)


def _take(values: np.ndarray | None, idx: np.ndarray | None) -> np.ndarray:
    if values is None or idx is None:
        return np.full(0 if idx is None else len(idx), np.nan)
    out = np.asarray(values, float)[np.maximum(idx, 0)]
    return np.where(idx >= 0, out, np.nan)


# ---------------------------------------------------------------------------------------------
# Panels
# ---------------------------------------------------------------------------------------------
def load_pyplot():
    """matplotlib.pyplot on the Agg back end (no display), imported on first use."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _panel_trajectory(ax, runs: Sequence[tuple[str, Series]]) -> None:
    ref = next((s.ref_xy for _, s in runs if s.ref_xy is not None), None)
    if ref is not None:
        ax.plot(ref[0], ref[1], "k--", lw=1.2, label="reference")
    for label, s in runs:
        ax.plot(s.x, s.y, lw=1.2, label=label)
    ax.set_xlabel("X [m]")
    ax.set_ylabel("Y [m]")
    ax.set_title("(a) trajectory")


def _panel_time(key: str, title: str, ylabel: str, deg: bool, with_ref: bool = False):
    def draw(ax, runs: Sequence[tuple[str, Series]]) -> None:
        if with_ref:
            ref = next((s for _, s in runs if s.ref_heading is not None), None)
            if ref is not None:
                ax.plot(ref.t, np.degrees(ref.ref_heading), "k--", lw=1.2, label="reference")
        for label, s in runs:
            v = np.asarray(getattr(s, key), float)
            if len(v) == len(s.t):
                ax.plot(s.t, np.degrees(v) if deg else v, lw=1.2, label=label)
        ax.set_xlabel("t [s]")
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        ax.grid(True, alpha=0.3)
    return draw


PANELS = (
    ("trajectory", _panel_trajectory),
    ("lateral_error", _panel_time("lateral_error", "(b) lateral error", "e_Y [m]", False)),
    ("heading_error", _panel_time("heading_error", "(c) heading error", "e_phi [deg]", True)),
    ("heading", _panel_time("yaw", "(d) heading", "phi [deg]", True, with_ref=True)),
    ("sideslip", _panel_time("sideslip", "(e) sideslip angle", "beta [deg]", True)),
    ("yaw_rate", _panel_time("yaw_rate", "(f) yaw rate", "r [deg/s]", True)),
)


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=110)
    load_pyplot().close(fig)
    return path


def _legend(ax, n_runs: int) -> None:
    handles, labels = ax.get_legend_handles_labels()
    if handles and (n_runs > 1 or "reference" in labels):
        ax.legend(fontsize=8)


def _draw_overview(runs: Sequence[tuple[str, Series]], path: Path, title: str) -> Path:
    plt = load_pyplot()
    fig, axes = plt.subplots(2, 3, figsize=(15, 8))
    for ax, (_name, draw) in zip(axes.flat, PANELS, strict=True):
        draw(ax, runs)
        _legend(ax, len(runs))
    fig.suptitle(title)
    fig.subplots_adjust(left=0.065, right=0.985, bottom=0.07, top=0.91, wspace=0.3, hspace=0.32)
    return _save(fig, path)


def _draw_panel(runs: Sequence[tuple[str, Series]], path: Path, title: str, draw) -> Path:
    fig, ax = load_pyplot().subplots(figsize=(7, 4))
    draw(ax, runs)
    _legend(ax, len(runs))
    fig.suptitle(title, fontsize=9)
    fig.subplots_adjust(left=0.13, right=0.97, bottom=0.13, top=0.87)
    return _save(fig, path)


@dataclass(frozen=True)
class _Figure:
    """One figure file and the call that draws and saves it (each figure is drawn on its
    own, so any split of them between processes gives the same files); ``cost``: its
    drawing time relative to a one-panel figure."""

    path: Path
    draw: Callable[[], Path]
    cost: float = 1.0


def _figure_jobs(runs: Sequence[tuple[str, Series]], out_dir: Path, prefix: str, title: str,
                 maxima: Mapping[str, float]) -> list[_Figure]:
    """Every figure of :func:`_draw`, in the order of its returned paths."""
    jobs: list[_Figure] = []

    def job(name: str, cost: float, fn: Callable[..., Path], *args) -> None:
        path = out_dir / f"{prefix}{name}.png"
        jobs.append(_Figure(path, lambda: fn(runs, path, *args), cost))

    job("overview", 4.0, _draw_overview, title)
    for name, draw in PANELS:
        job(name, 1.0, _draw_panel, title, draw)
    adaptive = [(label, s) for label, s in runs if len(s.diagnostics.get("stamp_ns", ()))
                and "np" in s.diagnostics]
    if adaptive:
        job("horizons_weights", 2.0, lambda _runs, path: _draw_adaptive(adaptive, path, title,
                                                                        maxima))
    job("wheel_torques", 1.5, _draw_torques, title)
    return jobs


def _split(jobs: Sequence[_Figure]) -> tuple[list[_Figure], list[_Figure]]:
    """Two groups of about equal cost (the costliest first, each to the lighter group)."""
    groups: tuple[list[_Figure], list[_Figure]] = ([], [])
    for job in sorted(jobs, key=lambda j: -j.cost):
        min(groups, key=lambda g: sum(j.cost for j in g)).append(job)
    return groups


def _draw(runs: Sequence[tuple[str, Series]], out_dir: Path, prefix: str, title: str,
          maxima: Mapping[str, float], workers: int = 1) -> list[Path]:
    load_pyplot()  # before a fork: the child starts with matplotlib loaded
    out_dir.mkdir(parents=True, exist_ok=True)
    jobs = _figure_jobs(runs, out_dir, prefix, title, maxima)
    mine, theirs = _split(jobs) if workers > 1 and len(jobs) > 1 else (jobs, [])
    child = _fork_figures(theirs) if theirs else None
    if theirs and child is None:  # no fork here: all in this process
        mine, theirs = jobs, []
    try:
        for job in mine:
            job.draw()
    finally:
        failed = child is not None and _wait_figures(child)
    if failed:  # the forked group did not finish: draw it here (same files)
        for job in theirs:
            job.draw()
    return [job.path for job in jobs]


def _fork_figures(jobs: Sequence[_Figure]) -> int | None:
    """Draw ``jobs`` in a forked child process (the other core); its pid, or None where
    there is no fork (the caller draws them then)."""
    if not hasattr(os, "fork"):
        return None
    try:
        pid = os.fork()
    except OSError:
        return None
    if pid:
        return pid
    code = 1  # the child: draw, then leave at once (nothing of the parent's to tear down)
    try:
        for job in jobs:
            job.draw()
        code = 0
    finally:
        os._exit(code)


def _wait_figures(pid: int) -> bool:
    """Wait for the child of :func:`_fork_figures`; True if it failed."""
    try:
        _, status = os.waitpid(pid, 0)
    except ChildProcessError:
        return True
    return not (os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0)


def _draw_adaptive(runs: Sequence[tuple[str, Series]], path: Path, title: str,
                   maxima: Mapping[str, float]) -> Path:
    plt = load_pyplot()
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    single = len(runs) == 1
    for label, s in runs:
        d = s.diagnostics
        tag = "" if single else f"{label}: "
        ax1.step(d["t_s"], d["np"], where="post", lw=1.2, label=f"{tag}Np")
        ax1.step(d["t_s"], d["nc"], where="post", lw=1.2, ls="--", label=f"{tag}Nc")
        for key, sym in (("q_y", "r_QY"), ("q_phi", "r_Qphi"), ("r_ddelta", "r_Rddelta"),
                         ("r_dmz", "r_RdMz")):
            if key in d:
                ax2.plot(d["t_s"], np.asarray(d[key], float) / maxima[key], lw=1.1,
                         label=f"{tag}{sym} = {key}/{maxima[key]:g}")
    ax1.set_ylabel("horizon [steps]")
    ax1.set_title("(a) prediction and control horizons")
    ax2.set_ylabel("weight ratio [-]")
    ax2.set_xlabel("t [s]")
    ax2.set_title("(b) adaptive weight ratios")
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
    fig.suptitle(title)
    fig.subplots_adjust(left=0.09, right=0.97, bottom=0.08, top=0.9, hspace=0.22)
    return _save(fig, path)


def _draw_torques(runs: Sequence[tuple[str, Series]], path: Path, title: str) -> Path:
    plt = load_pyplot()
    fig, axes = plt.subplots(len(runs), 1, figsize=(9, 3.2 * len(runs) + 0.6), sharex=True,
                             squeeze=False)
    for ax, (label, s) in zip(axes[:, 0], runs, strict=True):
        for i, wheel in enumerate(WHEELS):
            if len(s.torque):
                ax.plot(s.torque_t, s.torque[:, i], lw=1.0, label=f"T_{wheel}")
        ax.set_ylabel("wheel torque [N m]")
        ax.grid(True, alpha=0.3)
        ax.set_title(label if len(runs) > 1 else "in-wheel motor torques and yaw moment")
        lines, labels = ax.get_legend_handles_labels()
        top = ax
        if len(s.mz):
            top = ax.twinx()
            (ln,) = top.plot(s.mz_t, s.mz, "k:", lw=1.2, label="Mz demand")
            top.set_ylabel("Mz [N m]")
            lines, labels = [*lines, ln], [*labels, "Mz demand"]
        if lines:
            top.legend(lines, labels, fontsize=7, ncol=5, loc="upper right", framealpha=0.9)
    axes[-1, 0].set_xlabel("t [s]")
    h_in = 3.2 * len(runs) + 0.6          # the figure's height: margins fixed in inches
    fig.suptitle(title, y=1.0 - 0.15 / h_in)
    fig.subplots_adjust(left=0.1, right=0.9, bottom=0.55 / h_in, top=1.0 - 0.65 / h_in,
                        hspace=0.35)
    return _save(fig, path)


# ---------------------------------------------------------------------------------------------
# Public API
# ---------------------------------------------------------------------------------------------
def draw_figures(run: RunData, out_dir: str | Path, *, title: str | None = None,
                 q_y_max: float = 8000.0, q_phi_max: float = 5000.0,
                 r_ddelta_max: float = 80000.0, r_dmz_max: float = 60000.0,
                 workers: int = 1) -> list[Path]:
    """All figures of one run as PNG files in ``out_dir`` (created); returns their paths.

    ``overview.png`` (Fig. 5/7 panels a-f), ``trajectory.png``, ``lateral_error.png``,
    ``heading_error.png``, ``heading.png``, ``sideslip.png``, ``yaw_rate.png``,
    ``horizons_weights.png`` (Fig. 6, when MPC diagnostics were recorded) and
    ``wheel_torques.png``. The ``*_max`` are the weight maxima of eq. (23). ``workers=2``
    draws half of them in a forked process (``fourws run``: ~1.2 s of drawing on one core;
    the files are the same), for a caller that holds no lock or thread a child could need.
    """
    label = run.controller or "vehicle"
    title = title or " / ".join(x for x in (run.controller, run.scenario) if x) or str(run.path)
    maxima = {"q_y": q_y_max, "q_phi": q_phi_max, "r_ddelta": r_ddelta_max, "r_dmz": r_dmz_max}
    return _draw([(label, series_of(run))], Path(out_dir), "", title, maxima, workers)


def draw_comparison(runs: Mapping[str, RunData], out_dir: str | Path, title: str, *,
                    q_y_max: float = 8000.0, q_phi_max: float = 5000.0,
                    r_ddelta_max: float = 80000.0, r_dmz_max: float = 60000.0) -> list[Path]:
    """The same figures with several runs overlaid (label -> run), as the paper compares
    controllers; files are named ``comparison_<figure>.png``. Returns their paths."""
    if not runs:
        raise ValueError("draw_comparison: no runs given")
    maxima = {"q_y": q_y_max, "q_phi": q_phi_max, "r_ddelta": r_ddelta_max, "r_dmz": r_dmz_max}
    series = [(label, series_of(run)) for label, run in runs.items()]
    return _draw(series, Path(out_dir), "comparison_", title, maxima)


def figures_markdown(paths: Sequence[str | Path], relative_to: str | Path,
                     heading: str | None = None) -> str:
    """Markdown image lines for figures, with paths relative to the report's folder."""
    lines = [f"### {heading}", ""] if heading else []
    for p in paths:
        rel = Path(os.path.relpath(Path(p), Path(relative_to))).as_posix()
        lines.append(f"![{Path(p).stem.replace('_', ' ')}]({rel})")
    return "\n".join(lines) + "\n"


def _cell(v: Any) -> str:
    if isinstance(v, bool) or v is None:
        return str(v)
    if isinstance(v, float):
        return "n/a" if math.isnan(v) else f"{v:.5g}"
    return str(v)


def metrics_table_markdown(rows: Mapping[str, Mapping[str, Any]], keys: Sequence[str],
                           headers: Sequence[str] | None = None, first: str = "run") -> str:
    """A Markdown table: one row per name in ``rows``, one column per key of ``keys``."""
    heads = list(headers) if headers else list(keys)
    if len(heads) != len(keys):
        raise ValueError("metrics_table_markdown: headers and keys differ in length")
    out = [f"| {first} | " + " | ".join(heads) + " |", "|---|" + "---|" * len(keys)]
    for name, m in rows.items():
        out.append(f"| {name} | " + " | ".join(_cell(m.get(k)) for k in keys) + " |")
    return "\n".join(out) + "\n"
