"""``fourws tune``: one written tuning procedure for every controller, into the preset YAML.

``fourws tune SPEC.yaml [--workers N] [--check]`` (docs/bench.md, "Tuning", "The procedure"),
the same for every group of controllers (the spec's ``groups``):

1. **Candidates.** Each group's two free parameters (the MPC presets' ``scale_y_m``,
   ``scale_phi_deg``; ``lqr_ff``'s ``lqr_e1_max_m``, ``lqr_e2_max_deg``): the package defaults
   (``mpc.yaml``, never a previous result) times 2^(i/2) and 2^(j/2), i, j in the spec's
   ``grid_exponents``.
2. **Margin.** A candidate is kept only if every controller of the group has ρ ≤
   ``max_spectral_radius`` (``core.margins``) at every speed of ``margin.speeds_kmh`` in every
   condition of ``margin.conditions`` (its delay and dead time told to the controller). A
   group with no kept candidate is an error, not a silent default.
3. **Grip.** A kept candidate is kept only if every controller of the group, on every
   ``grip`` scenario (beyond the limit of grip) under every ``grip`` condition and seed,
   neither spins (``core.limit_metrics``: |β| ≥ ``SPIN_SIDESLIP_DEG``) nor aborts: stability
   beyond the limit is a constraint, as the margin is, not a score. A group with no candidate
   left is an error.
4. **Closed loop.** Every kept candidate runs every controller of the group on every tuning
   scenario under every tuning condition and seed (the in-process loop of ``fourws sweep``).
   A controller's score is its worst max |e_Y| (on the truth) over those runs, infinite if one
   aborts; the candidate's is the worst over the group's controllers. Exact pruning
   (:func:`tune`): a candidate already worse than the best complete one, or with a run that
   aborts, is abandoned; the choice is a full evaluation's.
5. **Choice.** The lowest score among the candidates whose kept grid neighbours (one step
   in i or j, :func:`neighbours`) complete every run: the choice sits on a plateau, not on
   the edge of a cliff that one noise draw did not show. Ties go to the lower worst ρ, then to
   the grid order. The chosen values are written into each preset of the group between the
   markers :data:`BEGIN` and :data:`END` of its ``mpc_node`` section; ``--check`` writes
   nothing and fails if the shipped presets differ from what the procedure chooses.

Everything is deterministic (seeded noise, a fixed job order), so a rerun reproduces the
shipped YAML; the report (``--report``) lists every candidate's ρ and score.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import re
import sys
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fourws_common.params import read_yaml_file
from fourws_mpc.core.config import MpcConfig

from .core.conditions import Condition, condition_from_mapping, condition_mapping
from .core.configs import (
    beside,
    controller_preset_path,
    controllers_dir,
    is_yaml_path,
    load_mpc_config,
    node_values,
    preset_label,
)

BEGIN = ("# -- tuned: fourws tune (its spec names this preset) writes the lines below; "
         "do not edit --")
END = "# -- end tuned --"
SPEC_KEYS = {"grid_exponents", "max_spectral_radius", "margin", "scenarios", "seeds",
             "conditions", "groups"}
#: optional keys (``grip`` absent: no step 3, as the specs of the studies before it)
OPTIONAL_KEYS = {"grip"}
#: digits kept in the written values (a rerun compares equal)
DIGITS = 4


@dataclass(frozen=True)
class Group:
    """Controllers that share the tuned parameters."""

    name: str
    controllers: tuple[str, ...]
    parameters: tuple[str, str]


@dataclass(frozen=True)
class TuningSpec:
    """The parsed spec (module docstring)."""

    grid_exponents: tuple[int, ...]
    max_spectral_radius: float
    speeds_kmh: tuple[float, ...]
    margin_scenario: str
    margin_conditions: Mapping[str, Condition]   # name -> its delays (the rest unused)
    scenarios: tuple[str, ...]
    seeds: tuple[int, ...]
    conditions: Mapping[str, Mapping[str, Any]]
    groups: tuple[Group, ...]
    grip_scenarios: tuple[str, ...] = ()
    grip_conditions: tuple[str, ...] = ()        # names among ``conditions``


def load_tuning_spec(path: str | Path) -> TuningSpec:
    """The spec; ``ValueError`` naming what is wrong. A relative ``.yaml`` scenario or
    controller preset is relative to the spec's folder (``core.configs.beside``); a preset
    given as a file is written in place (:func:`write_presets`)."""
    path = Path(path)
    d = read_yaml_file(path)
    if not isinstance(d, Mapping):
        raise ValueError(f"{path}: a tuning spec is a mapping of {sorted(SPEC_KEYS)}")
    missing = sorted(SPEC_KEYS - set(d))
    unknown = sorted(set(d) - SPEC_KEYS - OPTIONAL_KEYS)
    if missing or unknown:
        raise ValueError(f"{path}: missing {missing}, unknown {unknown}")
    for key in ("grid_exponents", "scenarios", "seeds"):   # an empty one: nothing to run
        if not isinstance(d[key], list) or not d[key]:
            raise ValueError(f"{path}: {key}: a non-empty list, got {d[key]!r}")
    for key in ("conditions", "groups", "margin"):
        if not isinstance(d[key], Mapping) or not d[key]:
            raise ValueError(f"{path}: {key}: a non-empty mapping, got {d[key]!r}")
    for name, g in d["groups"].items():
        if not isinstance(g, Mapping) or not isinstance(g.get("controllers"), list) or \
                not g["controllers"] or not isinstance(g.get("parameters"), list):
            raise ValueError(f"{path}: groups.{name}: a mapping of a non-empty list of "
                             "controllers and a list of parameters")
    m = d["margin"]
    if not m.get("speeds_kmh") or not isinstance(m.get("conditions"), Mapping):
        raise ValueError(f"{path}: margin needs at least one of speeds_kmh and of conditions")
    try:
        margin_conditions = {str(k): condition_from_mapping({**condition_mapping(v),
                                                             "name": str(k)})
                             for k, v in m["conditions"].items()}
        for name, v in d["conditions"].items():
            condition_from_mapping({**condition_mapping(v), "name": str(name)})
        for seed in d["seeds"]:
            condition_from_mapping({}, seed=seed)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    known = {f.name for f in dataclasses.fields(MpcConfig)}
    groups = []
    for name, g in d["groups"].items():
        params = tuple(str(p) for p in g["parameters"])
        if len(set(params)) != 2 or not set(params) <= known:
            raise ValueError(f"{path}: group {name}: two MPC parameters, got {list(params)}")
        groups.append(Group(str(name), tuple(beside(path, c) for c in g["controllers"]),
                            params))
    scen = tuple(beside(path, s) for s in d["scenarios"])
    grip = d.get("grip") or {}
    lists = isinstance(grip, Mapping) and all(
        isinstance(grip.get(k, []), list) for k in ("scenarios", "conditions"))
    grip_conditions = tuple(str(c) for c in grip.get("conditions", ())) if lists else ()
    if not lists or set(grip) - {"scenarios", "conditions"} or \
            bool(grip.get("scenarios")) != bool(grip_conditions) or \
            not set(grip_conditions) <= {str(k) for k in d["conditions"]}:
        raise ValueError(f"{path}: grip is a mapping of two lists, scenarios and conditions "
                         f"(names among conditions: {sorted(map(str, d['conditions']))}), "
                         "both or neither")
    if not all(isinstance(i, int) and not isinstance(i, bool) for i in d["grid_exponents"]):
        raise ValueError(f"{path}: grid_exponents: integers, got {d['grid_exponents']!r}")
    return TuningSpec(tuple(int(i) for i in d["grid_exponents"]),
                      float(d["max_spectral_radius"]),
                      tuple(float(v) for v in m["speeds_kmh"]), str(m["scenario"]),
                      margin_conditions,
                      scen, tuple(int(s) for s in d["seeds"]), dict(d["conditions"]),
                      tuple(groups),
                      tuple(beside(path, s) for s in grip.get("scenarios", ())),
                      grip_conditions)


def defaults(group: Group) -> dict[str, float]:
    """The package defaults (``mpc.yaml``) of the group's parameters."""
    values = node_values("mpc_node")
    return {p: float(values[p]) for p in group.parameters}


def candidates(spec: TuningSpec, group: Group) -> list[dict[str, float]]:
    """The grid of step 1, in grid order."""
    base = defaults(group)
    p, q = group.parameters
    return [{p: round(base[p] * 2.0 ** (i / 2.0), _digits(base[p])),
             q: round(base[q] * 2.0 ** (j / 2.0), _digits(base[q]))}
            for i in spec.grid_exponents for j in spec.grid_exponents]


def _digits(x: float) -> int:
    """Decimals that keep :data:`DIGITS` significant digits of ``x``."""
    return max(DIGITS - 1 - int(math.floor(math.log10(abs(x)))), 0) if x else DIGITS


def loops(spec: TuningSpec, group: Group, cand: Mapping[str, float]
          ) -> Iterator[tuple[str, str, float, Callable[..., Any]]]:
    """Step 2's linearised loops of a candidate: (controller, world, v_kmh, analyse),
    where ``analyse(fn)`` calls ``core.margins.margins`` or ``spectral_radius`` on that loop
    (the controller told of the world's delays, the plant given them)."""
    from fourws_sim.core.scenario import load_scenario

    vehicle = load_scenario(spec.margin_scenario).vehicle
    for c in group.controllers:
        for world, cond in spec.margin_conditions.items():
            n_d, dead = cond.delay_periods, cond.steer_dead_time_s
            cfg = load_mpc_config(c, {**cand, "input_delay_periods": n_d,
                                      "steer_dead_time_s": dead})
            for v_kmh in spec.speeds_kmh:
                yield c, world, v_kmh, functools.partial(_analyse, cfg, vehicle, v_kmh / 3.6,
                                                         n_d, dead)


def _analyse(cfg: MpcConfig, vehicle: Any, vx_mps: float, delay_periods: int,
             dead_time_s: float, fn: Callable[..., Any]) -> Any:
    return fn(cfg, vehicle, vx_mps, delay_periods=delay_periods, steer_dead_time_s=dead_time_s)


def worst_radius(spec: TuningSpec, group: Group, cand: Mapping[str, float]) -> float:
    """Step 2: the largest ρ over the group's controllers, speeds and worlds."""
    from .core.margins import spectral_radius

    return max(analyse(spectral_radius) for *_, analyse in loops(spec, group, cand))


def _radius_job(args: tuple[TuningSpec, Group, dict[str, float]]) -> float:
    return worst_radius(*args)


def _jobs(spec: TuningSpec, group: Group, cand: Mapping[str, float], grip: bool = False
          ) -> list[Any]:
    """A candidate's runs of step 4 (``grip``: of step 3), controller by controller in the
    group's order (the first controller is the one expected to score worst: the pruning of
    :func:`tune` then stops a losing candidate early)."""
    from .sweep import Job

    jobs = []
    for c in group.controllers:
        for name, raw in spec.conditions.items():
            if grip and str(name) not in spec.grip_conditions:
                continue
            for seed in spec.seeds:
                cond = condition_from_mapping({**condition_mapping(raw), "name": str(name)},
                                              seed=seed)
                cond = dataclasses.replace(cond, mpc_overrides={**cond.mpc_overrides, **cand})
                for s in (spec.grip_scenarios if grip else spec.scenarios):
                    jobs.append(Job(c, s, cond))
    return jobs


def _grip_failures(spec: TuningSpec, group: Group, kept: Sequence[tuple[int, Any, float]],
                   pool: Any) -> dict[int, list[str]]:
    """Step 3: per grid index of ``kept``, the controllers that fail a grip run, each with
    why: ``spins`` (|β| ≥ 10°, whether or not the run then aborts), ``aborts`` (the run
    ended early otherwise) or ``raises`` (the run failed: its error is printed)."""
    from .sweep import raised, run_job

    work = [(g, j) for g, c, _ in kept for j in _jobs(spec, group, c, grip=True)]
    failed: dict[int, list[str]] = {}
    for (g, _), row in zip(work, pool.map(run_job, [j for _, j in work]), strict=True):
        if row.get("completed") and not row.get("spin"):
            continue
        error = raised(row)
        why = "spins" if row.get("spin") else "raises" if error else "aborts"
        if error:
            print(f"[tune] {group.name}: a grip run {row['reason']}\n"
                  f"{row.get('traceback', '')}", file=sys.stderr)
        entry = f"{preset_label(row['controller'])} ({why})"
        if entry not in failed.get(g, []):
            failed.setdefault(g, []).append(entry)
    return failed


def shipped(group: Group) -> dict[str, float]:
    """The values the group's first preset holds now (what the last run chose)."""
    from .core.configs import load_mpc_config

    cfg = load_mpc_config(group.controllers[0])
    return {p: float(getattr(cfg, p)) for p in group.parameters}


def _score(row: Mapping[str, Any]) -> float:
    return float(row["max_abs_lateral_error_m"]) if row.get("completed") else math.inf


def neighbours(index: int, n: int) -> list[int]:
    """The grid indices next to ``index`` (one step in i or in j) on an ``n`` × ``n`` grid in
    grid order (:func:`candidates`)."""
    i, j = divmod(index, n)
    return [a * n + b for a, b in ((i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1))
            if 0 <= a < n and 0 <= b < n]


def tune(spec: TuningSpec, workers: int = 1, progress: bool = True
         ) -> tuple[dict[str, dict[str, float]], list[dict[str, Any]]]:
    """(chosen values per group, one report row per candidate step 2 kept): steps 1-5.

    Step 4 is evaluated with exact pruning: a candidate is abandoned as soon as one of its runs
    is worse than the best complete candidate's score (its own score, a maximum, can then only
    be worse). The candidate the presets hold now (:func:`shipped`) runs first and alone,
    ``workers`` of its runs at a time; then the next run of each of ``workers`` candidates at
    once, in grid order, so a losing candidate costs one run, not a batch. A good first bar
    prunes the rest sooner, and since pruning is strict and the
    choice compares (score, ρ, grid index), the order changes the time, never the choice,
    which is the one a full evaluation makes. Step 5 finishes the runs it needs: those of the
    best candidate's kept grid neighbours, and of any pruned candidate whose lower bound could
    beat the next best once the best is set aside. The report, in grid order, gives a pruned
    candidate's lower bound and marks the candidates step 5 set aside for an aborting
    neighbour."""
    from concurrent.futures import Executor, ProcessPoolExecutor

    class _Serial(Executor):
        def map(self, fn, *its, **_kw):  # type: ignore[override]
            return map(fn, *its)

    chosen: dict[str, dict[str, float]] = {}
    report: list[dict[str, Any]] = []
    with (ProcessPoolExecutor(max_workers=workers) if workers > 1 else _Serial()) as pool:
        for group in spec.groups:
            chosen[group.name], rows = _tune_group(spec, group, pool, max(workers, 1),
                                                   progress)
            report += rows
    return chosen, report


def _tune_group(spec: TuningSpec, group: Group, pool: Any, batch: int, progress: bool
                ) -> tuple[dict[str, float], list[dict[str, Any]]]:
    """One group's steps 1-5 (:func:`tune`): its chosen values and report rows."""
    from .sweep import run_job

    n = len(spec.grid_exponents)
    report: list[dict[str, Any]] = []
    cands = candidates(spec, group)
    radii = list(pool.map(_radius_job, [(spec, group, c) for c in cands]))
    kept = [(g, c, r) for g, (c, r) in enumerate(zip(cands, radii, strict=True))
            if r <= spec.max_spectral_radius]
    if progress:
        print(f"[tune] {group.name}: {len(kept)} of {len(cands)} candidates have "
              f"rho <= {spec.max_spectral_radius}", file=sys.stderr)
    if not kept:
        raise ValueError(f"group {group.name}: no candidate of the grid has a "
                         f"spectral radius <= {spec.max_spectral_radius}; widen "
                         "grid_exponents")
    failed = _grip_failures(spec, group, kept, pool) if spec.grip_scenarios else {}
    for g, c, r in kept:
        if g in failed:
            report.append({"group": group.name, **c, "worst_rho": round(r, 5),
                           "grip": "fails: " + ", ".join(failed[g]), "runs": 0})
    kept = [(g, c, r) for g, c, r in kept if g not in failed]
    if progress and spec.grip_scenarios:
        print(f"[tune] {group.name}: {len(kept)} of them neither spin nor abort beyond the "
              "limit (grip)", file=sys.stderr)
    if not kept:
        raise ValueError(f"group {group.name}: every candidate with a spectral radius <= "
                         f"{spec.max_spectral_radius} spins or aborts on a grip run")
    best: tuple[float, float, int] | None = None
    now = shipped(group)
    order = sorted(range(len(kept)), key=lambda k: kept[k][1] != now)
    jobs = {k: _jobs(spec, group, kept[k][1]) for k in order}
    done = dict.fromkeys(order, 0)
    by_ctrl: dict[int, dict[str, float]] = {k: {} for k in order}

    def score(k: int) -> float:
        return max(by_ctrl[k].values()) if by_ctrl[k] else 0.0

    def complete(k: int) -> bool:
        return done[k] == len(jobs[k])

    def run(work: list[tuple[int, Any]]) -> None:
        for (k, _), row in zip(work, pool.map(run_job, [j for _, j in work]),
                               strict=True):
            by_ctrl[k][row["controller"]] = max(by_ctrl[k].get(row["controller"], 0.0),
                                                _score(row))
            done[k] += 1

    def say(k: int) -> None:
        if progress:
            print(f"[tune] {group.name} {dict(kept[k][1])}: rho {kept[k][2]:.4f}, "
                  + (f"score {score(k):.4f} m" if complete(k) else
                     f"pruned after {done[k]} runs ("
                     + ("a run aborts)" if math.isinf(score(k)) else
                        f"> {best[0]:.4f} m)")),
                  file=sys.stderr)

    pending = list(order)
    while pending:
        # the first candidate (the presets' own, when on the grid) runs alone, a batch
        # of its runs at a time, to set the bar; then the next run of each of `batch`
        # candidates at once, so that a losing candidate is dropped after one run
        if best is None:
            k0 = pending[0]
            work = [(k0, j) for j in jobs[k0][done[k0]:done[k0] + batch]]
        else:
            work = [(k, jobs[k][done[k]]) for k in pending[:batch]]
        if not work:                      # a candidate without runs would never complete
            raise ValueError(f"tuning: group {group.name}: a candidate has no runs")
        run(work)
        for k in dict.fromkeys(k for k, _ in work):
            if not complete(k) and math.isfinite(score(k)) and (best is None
                                                                or score(k) <= best[0]):
                continue                  # exact pruning: a maximum only grows
            pending.remove(k)
            say(k)
            if complete(k) and (best is None or (score(k), kept[k][2], k) < best):
                best = (score(k), kept[k][2], k)

    # step 5: the best candidate whose kept grid neighbours all complete
    at = {g: k for k, (g, _, _) in enumerate(kept)}
    set_aside: set[int] = set()
    while True:
        b = min(((score(k), kept[k][2], k) for k in order
                 if complete(k) and k not in set_aside and math.isfinite(score(k))),
                default=None)
        near = [at[g] for g in neighbours(kept[b[2]][0], n) if g in at] if b else []
        todo = [k for k in dict.fromkeys(
                    [k for k in order if b is None or score(k) <= b[0]] + near)
                if not complete(k) and math.isfinite(score(k))]
        if todo:            # could beat b once finished, or b's neighbours (an abort is known)
            run([(k, j) for k in todo for j in jobs[k][done[k]:]])
            for k in todo:
                say(k)
            continue
        if b is None:
            raise ValueError(f"group {group.name}: every candidate aborts or sits next "
                             "to one that aborts; widen grid_exponents")
        if all(math.isfinite(score(k)) for k in near):
            best = b
            break
        set_aside.add(b[2])
        if progress:
            print(f"[tune] {group.name} {dict(kept[b[2]][1])}: set aside, a grid "
                  "neighbour aborts", file=sys.stderr)
    for k in sorted(order):
        c, r = kept[k][1], kept[k][2]
        report.append({"group": group.name, **c, "worst_rho": round(r, 5),
                       **({"grip": "pass"} if spec.grip_scenarios else {}),
                       "runs": done[k], "score_m": score(k) if complete(k) else None,
                       "pruned_above_m": None if complete(k) else score(k),
                       "set_aside": "yes" if k in set_aside else None,
                       **{f"max_ey_{preset_label(m)}": v
                          for m, v in by_ctrl[k].items()}})
    grid = {tuple(c.values()): g for g, c in enumerate(cands)}
    report.sort(key=lambda row: grid[tuple(row[p] for p in group.parameters)])
    return kept[best[2]][1], report


def preset_block(values: Mapping[str, float]) -> list[str]:
    """The lines between the markers (indented as a ``ros__parameters`` key)."""
    return [f"    {k}: {v!r}" for k, v in values.items()]


def presets_dir(spec_path: str | Path) -> Path:
    """Where the tuned presets are written: the source tree's
    ``src/fourws_bringup/config/controllers`` beside the spec's ``benchmarks/`` folder when
    there is one (a checkout), else the presets the package uses."""
    src = Path(spec_path).resolve().parent.parent / "src" / "fourws_bringup" / "config" / \
        "controllers"
    return src if src.is_dir() else controllers_dir()


def write_presets(spec: TuningSpec, chosen: Mapping[str, Mapping[str, float]],
                  directory: Path, check: bool = False) -> list[str]:
    """Write (or with ``check`` compare) each preset's tuned block in ``directory`` (a preset
    the spec gives as a file: in that file); the presets that differ."""
    differ = []
    for group in spec.groups:
        for c in group.controllers:
            path = Path(c) if is_yaml_path(c) else directory / f"{c}.yaml"
            if not path.is_file():
                raise ValueError(f"preset {c}: {path} not found")
            text = path.read_text(encoding="utf-8")
            new = replace_block(text, preset_block(chosen[group.name]), path)
            if new != text:
                differ.append(str(path))
                if not check:
                    tmp = path.with_name(path.name + ".tmp")   # a full disk never
                    try:                                         # truncates a preset
                        tmp.write_text(new, encoding="utf-8")
                        os.replace(tmp, path)
                    finally:
                        tmp.unlink(missing_ok=True)
    return differ


def replace_block(text: str, lines: list[str], where: Any = "preset") -> str:
    """``text`` with the tuned block replaced by ``lines`` (inserted at the end of the
    ``mpc_node`` parameters when it has none yet)."""
    pat = re.compile(rf"^ *{re.escape(BEGIN)}\n(?:.*\n)*? *{re.escape(END)}\n", re.M)
    block = "    " + BEGIN + "\n" + "".join(f"{ln}\n" for ln in lines) + "    " + END + "\n"
    if pat.search(text):
        return pat.sub(lambda _m: block, text, count=1)
    m = re.search(r"^(?:/\*\*/)?mpc_node:\n  ros__parameters:\n(?:    .*\n)*", text, re.M)
    if not m:
        raise ValueError(f"{where}: no 'mpc_node: ros__parameters:' section")
    return text[:m.end()] + block + text[m.end():]


def report_markdown(spec_path: str, chosen: Mapping[str, Mapping[str, float]],
                    report: list[dict[str, Any]]) -> str:
    """Per group: the choice, then every candidate step 2 kept: its worst ρ, whether it
    passed step 3 (grip) and its scores (m)."""
    out = [f"# Tuning ({Path(spec_path).name})", ""]
    for g, vals in chosen.items():
        out += [f"## {g}: " + ", ".join(f"{k} = {v:g}" for k, v in vals.items()), ""]
        rows = [r for r in report if r["group"] == g]
        keys: list[str] = []
        for r in rows:
            keys += [k for k in r if k not in keys and k != "group"]
        out.append("| " + " | ".join(keys) + " |")
        out.append("|" + "---|" * len(keys))
        for r in rows:
            out.append("| " + " | ".join(_fmt(r.get(k)) for k in keys) + " |")
        out.append("")
    return "\n".join(out)


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return "abort" if math.isinf(v) else f"{v:.4g}"
    return "" if v is None else str(v)


def only_groups(spec: TuningSpec, names: Sequence[str] | None) -> TuningSpec:
    """The spec with only the groups called ``names`` (None or empty: all of them); an
    unknown name raises ``ValueError``."""
    if not names:
        return spec
    known = [g.name for g in spec.groups]
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ValueError(f"--group {', '.join(unknown)}: not a group of the spec "
                         f"(groups: {', '.join(known)})")
    return dataclasses.replace(spec, groups=tuple(g for g in spec.groups if g.name in names))


def tune_cli(spec_path: str, workers: int, check: bool, report_path: str | None,
             presets: str | None = None, groups: Sequence[str] | None = None) -> int:
    """``fourws tune``; ``groups``: tune only these groups of the spec."""
    try:
        spec = only_groups(load_tuning_spec(spec_path), groups)
        directory = Path(presets) if presets else presets_dir(spec_path)
        for g in spec.groups:
            for c in g.controllers:
                controller_preset_path(c)
        chosen, report = tune(spec, workers)
        differ = write_presets(spec, chosen, directory, check=check)
    except (ValueError, OSError, KeyError) as exc:
        print(f"fourws tune: {exc}", file=sys.stderr)
        return 2
    if report_path:
        Path(report_path).write_text(report_markdown(spec_path, chosen, report),
                                     encoding="utf-8")
    for g, vals in chosen.items():
        print(f"{g}: " + ", ".join(f"{k}={v!r}" for k, v in vals.items()))
    if check:
        if differ:
            print("fourws tune --check: the shipped presets differ from the procedure's choice: "
                  + ", ".join(differ), file=sys.stderr)
            return 1
        print("fourws tune --check: the shipped presets are what the procedure chooses")
    else:
        print(f"wrote {len(differ)} preset(s)" + (": " + ", ".join(differ) if differ else ""))
    return 0
