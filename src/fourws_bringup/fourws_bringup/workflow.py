"""A run and its score: ``fourws run`` and ``fourws report`` (docs/graph.md, "Runs").

``fourws run``: the graph over topics, then metrics.json and figures from its bag;
``fourws report``: the same from a bag alone. ``fourws paper`` runs the former for each of its
configurations.
"""

from __future__ import annotations

import os
import sys
import threading
from pathlib import Path

from .core.conditions import IDEAL, Condition


def run_and_score(scenario: str, controller: str, out_dir: Path, *, force: bool = False,
                  mode: str = "lockstep", plots: bool = True, progress: bool = True,
                  compose: str = "none", condition: Condition = IDEAL,
                  namespace: str = "", domain_id: int | None = None,
                  via_adapter: bool = False) -> dict:
    """``fourws run``: one run over topics, then metrics.json and plots from its bag.

    ``compose``: the process layout (:func:`fourws_bringup.graph.graph_specs`), recorded in
    metrics.json; it changes the timing only, never a recorded value. ``condition``: the
    bench (``core.conditions``), recorded in metrics.json as ``condition`` and ``seed``.
    ``namespace``, ``domain_id``, ``via_adapter``: :func:`~fourws_bringup.runner.run_graph`.
    """
    from fourws_common.exit_codes import ExitCode
    from fourws_common.vehicle_info import load_vehicle_info
    from fourws_sim.core.scenario import load_scenario

    from .core.configs import check_preset
    from .graph import controller_preset
    from .outputs import RunError, prepare_out_dir
    from .runner import run_graph
    from .scoring import (
        limit_record,
        scenario_record,
        score_run,
        vehicle_record,
        write_metrics,
    )

    controller_preset(controller)
    try:
        check_preset(controller)
    except ValueError as exc:
        why = str(exc).removeprefix(f"{Path(controller)}: ")   # the file is named once
        raise RunError(f"controller preset '{controller}': {why}") from None
    try:
        load_vehicle_info(condition.vehicle or None)   # the controllers' part of the car
    except ValueError as exc:
        raise RunError(f"vehicle: {exc}") from None
    try:
        sc = load_scenario(scenario, vehicle=condition.vehicle or None)  # the plant's part
    except (ValueError, FileNotFoundError) as exc:
        why = str(exc).removeprefix(f"{Path(scenario)}: ")  # the file is named once
        raise RunError(f"scenario '{scenario}': {why}") from exc
    prepare_out_dir(out_dir, force)
    print(f"[fourws] {controller} on {sc.name}: {sc.summary()}", file=sys.stderr)
    prefetch = threading.Thread(target=_prefetch_scoring, args=(plots,), daemon=True,
                                name="fourws-prefetch")
    outcome = run_graph(scenario, controller, out_dir, mode=mode, progress=progress,
                        compose=compose, condition=condition, namespace=namespace,
                        domain_id=domain_id, via_adapter=via_adapter,
                        on_started=prefetch.start)   # after the nodes' own start-up
    if prefetch.ident is not None:         # started: the graph came up
        prefetch.join()                    # before the figures fork: no thread mid-import
    from .bag.run_data import read_run

    run = None
    try:
        run = read_run(out_dir)  # once, for the metrics and the figures
        metrics = score_run(out_dir, outcome, scenario=sc.name, controller=controller, run=run)
        metrics.update(limit_record(run, metrics, sc.path.lanes, sc.path.vehicle_width_m))
    except Exception as exc:  # noqa: BLE001 - the run's own record must still be written
        metrics = {"scenario": sc.name, "controller": controller, "completed": False,
                   "reason": f"{outcome.reason}; metrics failed: {exc}",
                   "wall_time_s": outcome.wall_time_s, "exit_code": int(ExitCode.ERROR)}
        if outcome.died:
            metrics["died"] = outcome.died
            metrics["died_error"] = outcome.died_error
    metrics.update(scenario_record(sc))
    metrics.update(vehicle_record(condition.vehicle))
    metrics["compose"] = compose
    if namespace.strip("/"):
        metrics["namespace"] = "/" + namespace.strip("/")
    if via_adapter:
        metrics["via_adapter"] = True
    metrics["condition"] = condition.name
    metrics["seed"] = condition.seed
    try:
        write_metrics(out_dir, metrics)
    except RunError as exc:
        exc.metrics = metrics            # still printed: nothing the run measured is lost
        if (out_dir / "bag").is_dir():
            exc.args = (f"{exc}; the bag keeps the run up to the failure (`fourws bag "
                        f"recover {out_dir}` once there is space)",)
        raise
    if plots and (out_dir / "bag").exists():
        try:
            from .report import draw_figures  # matplotlib: only when figures are drawn

            draw_figures(run if run is not None else read_run(out_dir), out_dir / "plots",
                         workers=min(2, os.cpu_count() or 1))
        except Exception as exc:  # noqa: BLE001
            print(f"[fourws] figures failed: {exc}", file=sys.stderr)
    return metrics


def _prefetch_scoring(plots: bool) -> None:
    """What scoring a bag needs, loaded while the graph runs and this process only watches
    it (started once the nodes are up, whose own imports it would slow): the bag reader, the
    limit metrics and their compiled path projection (numba's first call in a process costs
    ~0.4 s), and matplotlib when figures are drawn. Imports and a throwaway projection only:
    nothing a run records. A failure is left to the scoring after the run, which reports it.
    """
    try:
        import numpy as np

        from fourws_mpc.core.reference import Reference

        from .bag.run_data import read_run  # noqa: F401
        from .core.limit_metrics import limit_metrics  # noqa: F401

        x = np.linspace(0.0, 9.0, 10)
        Reference.from_arrays(x, 0.0 * x, 0.0 * x, 0.0 * x, 1.0 + 0.0 * x).errors(1.0, 0.1, 0.0)
        if plots:
            from .report import load_pyplot

            load_pyplot()
    except Exception:  # noqa: BLE001, S110 - only a head start; scoring imports for itself
        pass


def report_path(path: Path, out: Path | None = None) -> dict:
    """``fourws report``: metrics.json and figures recomputed from a bag or run folder.

    What the bag alone cannot give (the run's condition, seed, process layout, the scenario's
    and the car's records, the limit metrics, a dead node) is kept from the folder's
    metrics.json, the recomputed scores over it. A ``RunError`` (before the bag is read)
    when ``out`` cannot be written; a figure that fails is said, the metrics still written.
    """
    import json

    from .bag.run_data import read_run
    from .outputs import writable_dir
    from .report import draw_figures
    from .scoring import LIVE_OUTCOME, NO_STATUS, score_run, write_metrics

    if not path.exists():
        raise FileNotFoundError(f"{path}: no such bag or run folder")
    folder = path if (path / "bag").is_dir() else path.parent     # the run's own folder
    out = out or folder
    writable_dir(out)
    live: dict = {}
    try:
        live = json.loads((folder / "metrics.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        pass                                      # none, or unreadable: the scores alone
    live = live if isinstance(live, dict) else {}
    score = score_run(path)
    # the bag's scores win; the live record fills what the bag cannot give, and the outcome
    # too when the bag has no final status (a plant that died: the live run knew why)
    no_status = str(score.get("reason", "")).startswith(NO_STATUS)
    metrics = {**score, **{k: v for k, v in live.items()
                           if k not in score or (no_status and k in LIVE_OUTCOME)}}
    write_metrics(out, metrics)
    try:
        draw_figures(read_run(path), out / "plots")
    except Exception as exc:  # noqa: BLE001 - the metrics are written; the figures are said
        print(f"[fourws] figures failed: {exc}", file=sys.stderr)
    return metrics
