"""The ``fourws`` command line.

    fourws run --scenario NAME_OR_YAML --controller NAME --out DIR [--force] [--mode M]
               [--no-plots] [--compose {none,control,all}]
    fourws paper [--out DIR] [--force] [--only C@S ...] [--compose {none,control,all}]
                 [--conditions ideal realistic] [--seed N]
    fourws report BAG_OR_RUN [--out DIR]
    fourws replay BAG [--rate R] [--topics T ...] [--domain-id N]
    fourws bag recover BAG_OR_FILE.mcap [--out FIXED.mcap]
    fourws margins --controller NAME --scenario NAME_OR_YAML [--speed-kmh V]
                   [--delay-periods N] [--steer-dead-time-ms D] [--no-relaxation]
    fourws sweep SPEC.yaml --out DIR [--force] [--workers N | --scheduler tcp://HOST:8786]
    fourws tune SPEC.yaml [--workers N] [--check] [--report FILE] [--presets DIR]
                [--group NAME ...]
    fourws scenarios | fourws controllers

Run and report: docs/graph.md, "Runs"; replay and recover: docs/bags.md, "Replay",
"Recovery"; paper, margins, sweep and tune: docs/bench.md, "Tables 6-8", "Margins",
"Sweeps", "Tuning".
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from .core.conditions import IDEAL, load_condition
from .graph import COMPOSE_LAYOUTS
from .workflow import report_path, run_and_score


def _cmd_run(args: argparse.Namespace) -> int:
    from .outputs import RunError
    from .scoring import metrics_json

    try:
        condition = IDEAL
        if args.condition:
            try:
                condition = load_condition(args.condition, args.seed)
            except (ValueError, OSError) as exc:
                raise RunError(f"--condition {args.condition}: {exc}") from None
        if args.vehicle:
            condition = dataclasses.replace(condition, vehicle=args.vehicle)
        metrics = run_and_score(args.scenario, args.controller, Path(args.out),
                                force=args.force, mode=args.mode, plots=not args.no_plots,
                                compose=args.compose, condition=condition,
                                namespace=args.namespace, domain_id=args.domain_id,
                                via_adapter=args.via_adapter)
    except (RunError, ValueError) as exc:
        print(f"fourws run: {exc}", file=sys.stderr)
        if getattr(exc, "metrics", None) is not None:
            print(metrics_json(exc.metrics), end="")
        return int(getattr(exc, "exit_code", 2))
    print(metrics_json(metrics), end="")
    code = metrics.get("exit_code")  # fourws_common.exit_codes.ExitCode
    return int(code) if isinstance(code, int) else 1


def _cmd_paper(args: argparse.Namespace) -> int:
    from .outputs import RunError
    from .paper import run_paper

    try:
        return run_paper(Path(args.out), force=args.force, only=args.only,
                         compose=args.compose, conditions=tuple(args.conditions), seed=args.seed)
    except (RunError, ValueError) as exc:
        print(f"fourws paper: {exc}", file=sys.stderr)
        return 2


def _cmd_report(args: argparse.Namespace) -> int:
    from .bag.errors import BagError
    from .outputs import RunError
    from .scoring import metrics_json

    try:
        metrics = report_path(Path(args.path), Path(args.out) if args.out else None)
    except (BagError, FileNotFoundError, RunError) as exc:
        print(f"fourws report: {exc}", file=sys.stderr)
        return 2
    print(metrics_json(metrics), end="")
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from .replay import replay_cli

    return replay_cli(args.bag, rate=args.rate, topics=args.topics, domain_id=args.domain_id)


def _cmd_bag(args: argparse.Namespace) -> int:
    from .bag.errors import BagError
    from .bag.recovery import in_bag_folder, recover, recover_folder

    src = Path(args.file)
    try:
        if args.out is None and in_bag_folder(src):
            r = recover_folder(src)
            if r.kept_aside is None:
                print(f"{r.mcap} is already whole ({r.messages} messages); "
                      f"{r.metadata} rewritten from it")
            else:
                print(f"recovered {r.messages} messages into {r.mcap} (metadata.yaml updated); "
                      f"the truncated file is kept as {r.kept_aside}")
            return 0
        dst = Path(args.out) if args.out else src.with_name(src.stem + "_recovered.mcap")
        if dst.exists() and not args.force:          # never over a file without being told
            print(f"fourws bag recover: {dst} exists; use --force to overwrite it",
                  file=sys.stderr)
            return 2
        n = recover(src, dst)
    except (BagError, FileNotFoundError) as exc:
        print(f"fourws bag recover: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"fourws bag recover: {exc.filename or src}: {exc.strerror or exc}",
              file=sys.stderr)
        return 2
    print(f"recovered {n} messages from {src} into {dst}")
    return 0


def _cmd_margins(args: argparse.Namespace) -> int:
    import json

    import yaml

    from fourws_sim.core.scenario import load_scenario

    from .core.conditions import condition_from_mapping
    from .core.configs import load_mpc_config
    from .core.margins import margins

    try:
        overrides = {}
        for item in args.set or []:
            key, sep, value = item.partition("=")
            if not sep or not key:
                raise ValueError(f"--set {item!r}: expected KEY=VALUE")
            overrides[key.strip()] = yaml.safe_load(value)
        cfg = load_mpc_config(args.controller, overrides)
        sc = load_scenario(args.scenario)
        vx = args.speed_kmh / 3.6 if args.speed_kmh is not None else sc.speed_mps
        if not 1.0 <= vx <= 70.0:
            raise ValueError(f"--speed-kmh: {vx * 3.6:g} km/h outside 3.6..252")
        plant = condition_from_mapping({"delay_periods": args.delay_periods,
                                        "steer_dead_time_ms": args.steer_dead_time_ms})
        m = margins(cfg, sc.vehicle, vx, delay_periods=plant.delay_periods,
                    steer_dead_time_s=plant.steer_dead_time_s,
                    relaxation=not args.no_relaxation)
    except (ValueError, FileNotFoundError) as exc:
        print(f"fourws margins: {exc}", file=sys.stderr)
        return 2
    out = {"controller": args.controller, "scenario": sc.name, "speed_kmh": vx * 3.6,
           "delay_periods": args.delay_periods, "steer_dead_time_ms": args.steer_dead_time_ms,
           "tyre_relaxation": not args.no_relaxation, "mpc_overrides": overrides,
           **m.as_dict()}
    print(json.dumps(out, indent=2))
    return 0


def _cmd_sweep(args: argparse.Namespace) -> int:
    from .sweep import sweep_cli

    return sweep_cli(args.spec, args.out, args.workers, args.scheduler, force=args.force)


def _cmd_tune(args: argparse.Namespace) -> int:
    from .tuning import tune_cli

    return tune_cli(args.spec, args.workers, args.check, args.report, args.presets,
                    args.group)


def _cmd_list(kind: str) -> int:
    from fourws_sim.core.scenario import list_scenarios

    from .core.configs import list_controllers

    for name in (list_scenarios() if kind == "scenarios" else list_controllers()):
        print(name)
    return 0


COMPOSE_CHOICES = tuple(COMPOSE_LAYOUTS)
COMPOSE_HELP = ("process layout: none (one process per node), control (MPC, speed PID and "
                "allocator in one container process) or all (the plant too); same nodes, "
                "parameters, topics and results, fewer processes to wake each step")


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="fourws", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)

    r = sub.add_parser("run", help="run one scenario with one controller over topics")
    r.add_argument("--scenario", required=True, help="scenario name or YAML path")
    r.add_argument("--controller", required=True, help="controller preset name or YAML path")
    r.add_argument("--out", required=True, help="output folder (bag/, metrics.json, plots/)")
    r.add_argument("--force", action="store_true", help="overwrite an existing output folder")
    r.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep",
                   help="lockstep: each step waits for every command (deterministic, as fast "
                        "as the graph); realtime: the plant steps on a 10 ms wall timer")
    r.add_argument("--no-plots", action="store_true", help="skip the figures")
    r.add_argument("--compose", choices=COMPOSE_CHOICES, default="none", help=COMPOSE_HELP)
    r.add_argument("--condition", default=None,
                   help="the bench: a shipped condition's name (realistic), a condition "
                        "YAML, or SPEC.yaml#NAME for a condition of a sweep spec (e.g. "
                        "benchmarks/robustness.yaml#all); default ideal")
    r.add_argument("--seed", type=int, default=None, help="noise seed (default: the "
                   "condition's, else 0)")
    r.add_argument("--vehicle", default=None, help="the car: a shipped car's name ("
                   "fourws_common/config/vehicles) or a car file; the plant and every "
                   "controller read it (default: the paper's car)")
    r.add_argument("--namespace", default="", help="ROS namespace of every node and its "
                   "topics (e.g. car1); /diagnostics stays global, the simulated clock "
                   "moves into the namespace")
    r.add_argument("--domain-id", type=int, default=None, help="ROS_DOMAIN_ID to run in "
                   "(default: a free one of this host, so parallel runs never meet)")
    r.add_argument("--via-adapter", action="store_true", help="feed the controllers through "
                   "adapter_node from standard messages (Odometry, Imu, JointState), as on "
                   "another car or simulator")
    r.set_defaults(func=_cmd_run)

    p = sub.add_parser("paper", help="run the paper's eight configurations and print Tables 6-8")
    p.add_argument("--out", default="runs/paper",
                   help="output folder: one run folder each, figures/, report.md")
    p.add_argument("--force", action="store_true", help="overwrite an existing output folder")
    p.add_argument("--only", nargs="*", help="subset of runs, as controller@scenario")
    p.add_argument("--compose", choices=COMPOSE_CHOICES, default="none", help=COMPOSE_HELP)
    p.add_argument("--conditions", nargs="+", choices=("ideal", "realistic"),
                   default=["ideal", "realistic"], help="ideal: the paper's setting; "
                   "realistic: the shipped realistic condition (noise, delays, estimated "
                   "tyre forces); default both")
    p.add_argument("--seed", type=int, default=0, help="noise seed of the realistic world")
    p.set_defaults(func=_cmd_paper)

    rep = sub.add_parser("report", help="metrics and figures from a recorded bag or run folder")
    rep.add_argument("path", help="run folder, bag folder or .mcap file")
    rep.add_argument("--out", help="folder for metrics.json and plots/ (default: beside bag)")
    rep.set_defaults(func=_cmd_report)

    rp = sub.add_parser("replay", help="publish a bag's topics again, with /clock")
    rp.add_argument("bag", help="run folder, bag folder or .mcap file")
    rp.add_argument("--rate", type=float, default=1.0, help="1.0 real time; 0 as fast as possible")
    rp.add_argument("--topics", nargs="*", help="topics to replay (default: all recorded)")
    rp.add_argument("--domain-id", type=int, default=None,
                    help="ROS_DOMAIN_ID (default: the environment's)")
    rp.set_defaults(func=_cmd_replay)

    b = sub.add_parser("bag", help="bag utilities")
    bsub = b.add_subparsers(dest="bagcmd", required=True)
    rec = bsub.add_parser("recover", help="rewrite a truncated .mcap whole")
    rec.add_argument("file", help="a run or bag folder, or an .mcap file, to rewrite (e.g. cut "
                                  "short by kill -9); a bag folder is repaired in place: its "
                                  ".mcap rewritten, metadata.yaml pointed at it, the cut file "
                                  "kept as NAME.mcap.truncated")
    rec.add_argument("--out", help="write the recovered file here instead and leave the bag "
                                   "as it is (default for a bare .mcap: FILE_recovered.mcap "
                                   "beside it)")
    rec.add_argument("--force", action="store_true", help="overwrite an existing --out file "
                     "(or FILE_recovered.mcap)")
    rec.set_defaults(func=_cmd_bag)

    g = sub.add_parser("margins", help="stability margins of the linearised lateral loop "
                       "(spectral radius per period, dominant frequency, gain and phase "
                       "margins of the steering loop) as JSON")
    g.add_argument("--controller", required=True, help="controller preset name or YAML path")
    g.add_argument("--scenario", required=True, help="scenario (its vehicle and speed)")
    g.add_argument("--speed-kmh", type=float, default=None, help="speed (default: the "
                   "scenario's)")
    g.add_argument("--delay-periods", type=int, default=0, choices=range(0, 11),
                   metavar="N", help="computation delay in control periods")
    g.add_argument("--steer-dead-time-ms", type=float, default=0.0,
                   help="steering dead time (rounded to control periods)")
    g.add_argument("--no-relaxation", action="store_true", help="tyres without relaxation")
    g.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override an MPC parameter of the preset (repeatable), e.g. "
                        "--set prediction_model=single_track_actuators --set "
                        "input_delay_periods=1 (the controller's known delay)")
    g.set_defaults(func=_cmd_margins)

    w = sub.add_parser("sweep", help="controllers x scenarios x conditions x seeds in the "
                       "in-process loop: results.csv and summary.md")
    w.add_argument("spec", help="sweep spec YAML (see fourws_bringup.sweep)")
    w.add_argument("--out", required=True, help="output folder")
    w.add_argument("--force", action="store_true", help="replace an existing sweep folder")
    w.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    w.add_argument("--scheduler", default=None, help="run on the Dask distributed cluster of "
                   "this scheduler address (e.g. tcp://host:8786) instead of local processes")
    w.set_defaults(func=_cmd_sweep)

    t = sub.add_parser("tune", help="the one tuning procedure of every controller "
                       "(fourws_bringup.tuning): writes the tuned block of the presets")
    t.add_argument("spec", help="tuning spec YAML (benchmarks/tuning.yaml)")
    t.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    t.add_argument("--check", action="store_true", help="write nothing; exit 1 if the "
                   "presets differ from the procedure's choice")
    t.add_argument("--report", default=None, help="write every candidate's rho and score "
                   "(Markdown) here")
    t.add_argument("--presets", default=None, help="presets folder to write or check for "
                   "the presets the spec names (default: the checkout's "
                   "src/fourws_bringup/config/controllers beside the spec, else the installed "
                   "presets); a preset the spec gives as a .yaml file is written in place")
    t.add_argument("--group", action="append", default=None, metavar="NAME",
                   help="tune only this group of the spec (repeatable; default: every group)")
    t.set_defaults(func=_cmd_tune)

    sub.add_parser("scenarios", help="list scenario names").set_defaults(
        func=lambda a: _cmd_list("scenarios"))
    sub.add_parser("controllers", help="list controller presets").set_defaults(
        func=lambda a: _cmd_list("controllers"))
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


#: Commands after which the ``fourws`` process ends at once (:func:`entry`): they leave no
#: thread, child process or temporary file for the interpreter to clean up.
FAST_EXIT_COMMANDS = frozenset({"run"})


def entry() -> None:
    """The ``fourws`` executable: :func:`main`, then, after a command of
    :data:`FAST_EXIT_COMMANDS`, ``os._exit`` with its code once the output is flushed
    (``fourws_common.fast_exit``: the interpreter's teardown took 0.25 s of every
    ``fourws run``); any other command exits as usual."""
    code = main()
    if sys.argv[1:2] and sys.argv[1] in FAST_EXIT_COMMANDS:
        from fourws_common.fast_exit import exit_now

        exit_now(code)
    raise SystemExit(code)


if __name__ == "__main__":
    raise SystemExit(main())
