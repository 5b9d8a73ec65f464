"""One closed-loop run over real topics: start the graph, record it, stop it, score it.

``run(scenario, controller, out_dir)`` starts plant, MPC, speed PID, allocator and recorder
as separate processes with the supervisor (their package YAML plus the controller preset as
``--params-file``), shows simulated time as it goes, waits for the plant to end the scenario,
stops the graph cleanly and writes ``out_dir/metrics.json`` computed from the recorded bag
alone (the same code as ``fourws report``) plus ``out_dir/plots/``. A node that dies stops
the run; the bag is kept and metrics.json says which node died and its last error line.

The outcome of a run comes from two records that do not depend on DDS timing: the plant's
exit status (:class:`fourws_common.exit_codes.ExitCode`: completed, aborted, timeout) and the
final status JSON it writes to ``logs/plant_status.json`` before it exits. The /run/status
monitor only shows progress.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from fourws_common.exit_codes import RUN_END_CODES, ExitCode
from fourws_common.topics import (
    CLOCK,
    RUN_STATUS,
    VEHICLE_GROUND_TRUTH,
    VEHICLE_IMU,
    VEHICLE_JOINT_STATES,
    VEHICLE_STATE,
)

from .core.conditions import IDEAL, Condition, node_parameters
from .core.configs import controller_preset_path, node_values, params_files
from .supervisor import (
    DomainLease,
    NodeDied,
    NodeSpec,
    Supervisor,
    SupervisorError,
    dds_environment,
    normalise_namespace,
)

RECORDER_NICE = 10  # niceness added to the recorder process
#: Process layouts of a run: container process name and the nodes it hosts (None: one
#: process per node). The recorder is never composed: it is off the control chain.
COMPOSE_LAYOUTS: dict[str, tuple[str, tuple[str, ...]] | None] = {
    "none": None,
    "control": ("control_container", ("mpc_node", "speed_pid_node", "allocator_node")),
    "all": ("node_container", ("plant_node", "mpc_node", "speed_pid_node", "allocator_node")),
}


class RunError(RuntimeError):
    """A run could not be started (bad arguments, existing output, unknown preset): exit
    code 2 (``exit_code``)."""

    exit_code = ExitCode.BAD_CONFIG


class OutputError(RunError):
    """The output could not be written for want of space (a full disk, a quota): not the
    user's argument, so exit code 1."""

    exit_code = ExitCode.ERROR


#: errors of a file system that is full, not of a bad path
NO_SPACE = frozenset({errno.ENOSPC, errno.EDQUOT})


def output_error(path: Path, exc: OSError, what: str = "cannot write") -> RunError:
    """The one-line error for an ``OSError`` on ``path``: an :class:`OutputError` naming the
    file system when it is full, a :class:`RunError` (bad argument) otherwise."""
    if exc.errno in NO_SPACE:
        return OutputError(f"{what} {path}: {exc.strerror} (the disk holding {path.parent} "
                           "is full)")
    return RunError(f"{what} {path}: {exc.strerror or exc}")


def controller_preset(name_or_path: str) -> Path:
    """Path of a controller preset (:func:`fourws_bringup.core.configs.controller_preset_path`),
    its error as a ``RunError``."""
    try:
        return controller_preset_path(name_or_path).resolve()
    except ValueError as exc:
        raise RunError(f"unknown controller '{name_or_path}': {exc}") from None


def scenario_arg(name_or_path: str) -> str:
    """A scenario name stays a name; a YAML path becomes absolute for the plant process."""
    p = Path(name_or_path)
    return str(p.resolve()) if p.suffix in (".yaml", ".yml") else name_or_path


#: What ``fourws run`` writes into its output folder; ``--force`` deletes nothing else.
RUN_FOLDER_ENTRIES = ("metrics.json", "bag", "logs", "plots")


def run_folder_problem(folder: Path) -> str | None:
    """Why ``folder`` is not a fourws run folder, or None if it is one: it holds only what
    ``fourws run`` writes (:data:`RUN_FOLDER_ENTRIES`), among them ``metrics.json``,
    ``bag/metadata.yaml`` or ``logs/`` (a run that died before its bag had any)."""
    names = sorted(p.name for p in folder.iterdir())
    other = [n for n in names if n not in RUN_FOLDER_ENTRIES]
    if other:
        more = f" and {len(other) - 5} more" if len(other) > 5 else ""
        return f"it holds {', '.join(repr(n) for n in other[:5])}{more}"
    if not ((folder / "metrics.json").is_file() or (folder / "bag" / "metadata.yaml").is_file()
            or (folder / "logs").is_dir()):
        return "it has no metrics.json, bag/metadata.yaml or logs/"
    return None


def writable_dir(out_dir: Path) -> None:
    """Create ``out_dir`` (and its parents) if needed and check a file can be made in it;
    a ``RunError`` in one line otherwise (an existing file, a read-only place)."""
    import tempfile

    if out_dir.exists() and not out_dir.is_dir():
        raise RunError(f"output folder {out_dir} is an existing file, not a folder")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out_dir):
            pass
    except OSError as exc:
        raise output_error(out_dir, exc, "cannot write output folder") from None


def prepare_out_dir(out_dir: Path, force: bool, *,
                    problem: Callable[[Path], str | None] = run_folder_problem,
                    what: str = "fourws run folder (" + ", ".join(RUN_FOLDER_ENTRIES) + ")",
                    replace: bool = True) -> None:
    """Make ``out_dir`` a writable folder for a run's output.

    An existing, non-empty folder is refused unless ``force``; with ``force`` it is emptied
    (``replace``; else its content stays for the command to overwrite) only if ``problem``
    (:func:`run_folder_problem` by default) finds it is fourws output (``what`` names the
    kind in the message). Any other folder is refused whole, nothing in it deleted.
    A file in the way, or a place that cannot be written, is a ``RunError`` too.
    """
    if out_dir.exists() and not out_dir.is_dir():
        raise RunError(f"output folder {out_dir} is an existing file, not a folder")
    try:
        non_empty = out_dir.is_dir() and any(out_dir.iterdir())
    except OSError as exc:
        raise RunError(f"cannot read output folder {out_dir}: {exc.strerror or exc}") from None
    if non_empty:
        if not force:
            raise RunError(f"output folder {out_dir} exists and is not empty; "
                           "use --force to overwrite it")
        try:
            why = problem(out_dir)
        except OSError as exc:
            why = f"cannot look inside it: {exc.strerror or exc}"
        if why is not None:
            raise RunError(f"output folder {out_dir} is not a {what}: {why}; --force replaces "
                           "only fourws output or an empty folder, so nothing was deleted")
        if replace:
            try:
                shutil.rmtree(out_dir)
            except OSError as exc:
                raise RunError(f"cannot replace output folder {out_dir}: "
                               f"{exc.strerror or exc}") from None
    writable_dir(out_dir)


def graph_specs(scenario: str, controller: str, bag_dir: Path | None, mode: str = "lockstep",
                extra_plant: dict | None = None, compose: str = "none",
                status_file: Path | None = None, use_sim_time: bool = False,
                condition: Condition = IDEAL, namespace: str = "",
                via_adapter: bool = False) -> list[NodeSpec]:
    """The node list of a run: every node with its package YAML and the controller preset.

    ``compose`` (:data:`COMPOSE_LAYOUTS`) picks the processes: ``none``, one per node;
    ``control``, the MPC, speed PID and allocator in one container process; ``all``, the plant
    too. Same nodes, parameters and topics in every layout (:mod:`fourws_bringup.container`);
    the recorder always has a process of its own. ``status_file``: where the plant writes
    its final status; ``use_sim_time``: every node's clock follows /clock; ``condition``
    (``core.conditions``): the bench, as node parameters (``node_parameters``);
    ``namespace``: every node's (its topics follow; ``/diagnostics`` stays global, the
    clock moves with the simulation, :func:`clock_remap`), so several runs can share a
    domain. ``via_adapter``: the controllers get their state the way they would on another
    car: the plant publishes standard messages (Odometry, Imu, JointState) and
    ``adapter_node`` builds ``vehicle/state`` from them (the plant's own goes to
    ``vehicle/state_direct``, which nothing reads).
    """
    if compose not in COMPOSE_LAYOUTS:
        raise RunError(f"compose layout '{compose}' is not one of {sorted(COMPOSE_LAYOUTS)}")
    if via_adapter and compose == "all":
        raise RunError("via_adapter: the plant's remapped state cannot share a container "
                       "process with the controllers (use compose none or control)")
    controller_preset(controller)

    def files(node: str) -> list[str]:
        return [str(f) for f in params_files(node, controller)]

    subscribers = 3 + (1 if bag_dir is not None else 0)
    plant_params = {"scenario": scenario_arg(scenario), "mode": mode,
                    "wait_for_subscribers": subscribers,
                    "wait_for_reference_subscribers": subscribers}
    if status_file is not None:
        plant_params["status_file"] = str(status_file)
    bench = node_parameters(condition)
    plant_params.update(bench["plant_node"])
    plant_params.update(extra_plant or {})
    sync = "lockstep" if mode == "lockstep" else "latest"
    # Recording in lockstep: each controller answers its first state only once its outputs
    # have matched every subscriber of the graph, the recorder among them. The recorder joins
    # last and cannot get a volatile first message again (the control chain can: the plant
    # republishes a waiting state and the controllers answer it from their caches).
    waits: dict[str, dict] = {}
    if bag_dir is not None and mode == "lockstep":
        waits = {
            # mpc_command: plant, allocator, recorder; mpc_diagnostics: recorder
            "mpc_node": {"wait_for_subscribers": 4},
            "speed_pid_node": {"wait_for_subscribers": 2},   # drive_command: allocator, rec.
            "allocator_node": {"wait_for_subscribers": 2},   # wheel_torques: plant, recorder
        }
    specs = [NodeSpec("plant_node", "fourws_sim", "plant_node", params_files=files("plant_node"),
                      parameters=plant_params, end_codes=RUN_END_CODES),
             *_control_nodes(controller, sync, bench, waits)]
    if via_adapter:
        plant_params.update(publish_standard_sensors=True, wait_for_subscribers=0)
        specs[0].remappings[VEHICLE_STATE.ros_name] = VEHICLE_STATE.ros_name + "_direct"
        specs.insert(1, NodeSpec("adapter_node", "fourws_bringup", "adapter_node",
                                 params_files=files("adapter_node"),
                                 parameters={"wait_for_subscribers": subscribers,
                                             "mu_nominal": float(condition.mu_nominal),
                                             **{k: v for k, v in bench["plant_node"].items()
                                                if k == "vehicle_file"}}))
    _place(specs, namespace, use_sim_time)
    specs = _layout(specs, compose)
    recorder_gate: dict = {"start_gate_topic": VEHICLE_STATE.name}
    if waits and not via_adapter:
        # No settle time for the start gate (its 0.5 s covers a publisher that has not yet
        # matched the recorder back when the recorder sees it): here every controller answers
        # only once its outputs have matched the recorder (``waits``; a state that came
        # before is answered as soon as they have), and the plant starts only once it has
        # matched the recorder's /vehicle/state subscription, which the recorder announces
        # after its other subscriptions. The 0.5 s were start-up time on every run.
        recorder_gate["start_gate_settle_s"] = 0.0
    if bag_dir is not None:
        # The recorder is off the control chain (it buffers and writes chunks), so it yields
        # the CPU to the nodes the next step waits on: on 2 cores this cut the median step
        # time by about 10 % (docs/architecture.md, "Timing").
        specs.append(NodeSpec("recorder_node", "fourws_bringup", "recorder_node",
                              params_files=files("recorder_node"),
                              parameters={"output_dir": str(bag_dir), **recorder_gate,
                                          # rosbag2's --use-sim-time: in lockstep the
                                          # bag's log times are the simulated ones, so
                                          # ros2 bag play paces it at the simulated rate
                                          "use_sim_time": use_sim_time or mode == "lockstep",
                                          "topics": recorded_topics(condition,
                                                                    via_adapter)},
                              nice=RECORDER_NICE, namespace=namespace,
                              remappings=clock_remap(namespace),
                              stop_stage=1))  # it outlives the writers it records
    return specs


#: The control stack: what a user puts on their own plant or simulator.
CONTROL_NODES = ("mpc_node", "speed_pid_node", "allocator_node")


def _control_nodes(controller: str, sync: str, bench: dict[str, dict],
                   waits: dict[str, dict]) -> list[NodeSpec]:
    """MPC, speed PID and allocator, each with its package YAML and the preset."""
    def spec(name: str, package: str, extra: dict) -> NodeSpec:
        return NodeSpec(name, package, name,
                        params_files=[str(f) for f in params_files(name, controller)],
                        parameters={**extra, "sync": sync, **waits.get(name, {})})

    return [spec("mpc_node", "fourws_mpc", bench["mpc_node"]),
            spec("speed_pid_node", "fourws_torque_alloc", bench["speed_pid_node"]),
            spec("allocator_node", "fourws_torque_alloc", bench["allocator_node"])]


def _layout(specs: list[NodeSpec], compose: str) -> list[NodeSpec]:
    """``specs`` in the processes of a :data:`COMPOSE_LAYOUTS` layout."""
    layout = COMPOSE_LAYOUTS[compose]
    if layout is None:
        return specs
    name, hosted = layout
    inside = [s for s in specs if s.name in hosted]
    return [s for s in specs if s.name not in hosted] + [NodeSpec.compose(name, inside)]


def control_specs(controller: str, sync: str = "latest", *, compose: str = "none",
                  use_sim_time: bool = False, condition: Condition = IDEAL,
                  namespace: str = "") -> list[NodeSpec]:
    """The control stack alone (:data:`CONTROL_NODES`), for a user's own plant or simulator:
    the same nodes and parameters as in :func:`graph_specs`. ``sync``: ``latest`` (answer
    the newest state, for a plant on its own clock) or ``lockstep`` (answer every state,
    for a plant that waits for the commands); ``compose``: ``none`` or ``control``."""
    if compose not in ("none", "control"):
        raise RunError(f"compose layout '{compose}' is not one of ['control', 'none'] for the "
                       "control stack alone")
    if sync not in ("latest", "lockstep"):
        raise RunError(f"sync '{sync}' is not one of ['latest', 'lockstep']")
    controller_preset(controller)
    specs = _control_nodes(controller, sync, node_parameters(condition), {})
    _place(specs, namespace, use_sim_time, own_clock=False)  # the user's plant has the clock
    return _layout(specs, compose)


def clock_remap(namespace: str) -> dict[str, str]:
    """The remapping that gives a simulation in ``namespace`` its own clock: ``/clock`` ->
    ``/ns/clock`` (none in the root namespace). Nodes publish and read the global /clock, as
    ROS expects; two simulated cars in one domain would mix their times on it, so a run in a
    namespace moves its clock with it (a user's own car has no simulated clock)."""
    ns = normalise_namespace(namespace)
    return {} if ns == "/" else {CLOCK.name: f"{ns}{CLOCK.name}"}


def _place(specs: list[NodeSpec], namespace: str, use_sim_time: bool,
           own_clock: bool = True) -> None:
    """Every spec in ``namespace`` (with the namespace's own clock, :func:`clock_remap`, for
    a simulation), on sim time if asked."""
    for spec in specs:
        spec.namespace = normalise_namespace(namespace)
        if own_clock:
            spec.remappings.update(clock_remap(namespace))
        if use_sim_time:
            spec.parameters["use_sim_time"] = True


def recorded_topics(condition: Condition, via_adapter: bool = False) -> list[str]:
    """recorder.yaml's topics; /vehicle/ground_truth only where the plant publishes it (a
    realistic condition), /vehicle/imu and /vehicle/joint_states only on the adapter path,
    so the recorder's start gate never waits for a silent topic."""
    topics = list(node_values("recorder_node")["topics"])
    silent = set() if via_adapter else {VEHICLE_IMU.name, VEHICLE_JOINT_STATES.name}
    if not node_parameters(condition)["plant_node"].get("publish_ground_truth"):
        silent.add(VEHICLE_GROUND_TRUTH.name)
    return [t for t in topics if t not in silent]


@dataclass
class RunOutcome:
    """How a run ended. ``status``: the plant's final status (its ``status_file``), or None
    when the plant left none (it died); ``exit_code`` the plant's (or the container's)."""

    completed: bool
    reason: str
    wall_time_s: float
    sim_time_s: float
    steps: int
    died: str | None = None
    exit_code: int | None = None
    status: dict | None = None
    died_error: str = ""

    @property
    def code(self) -> ExitCode:
        """The exit code ``fourws run`` gives for this outcome: the plant's, when it ended the
        run with a final status; ERROR otherwise (a death, no status, a graph failure)."""
        if self.died:
            return ExitCode.ERROR
        if self.exit_code == ExitCode.INTERRUPTED:
            return ExitCode.INTERRUPTED
        if self.status is None:
            return ExitCode.ERROR
        if self.exit_code in RUN_END_CODES:
            return ExitCode(self.exit_code)
        return ExitCode.ERROR


def read_status_file(path: Path) -> dict | None:
    """The plant's final status JSON, or None if it is missing or unreadable."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


class _Monitor:
    """A small rclpy node in the run's domain that reads the plant's /run/status: progress
    from its heartbeats, the end and the plant's own wall time from its last message. It
    takes no per-step topic, so watching a run costs the graph nothing per step."""

    def __init__(self, domain_id: int, namespace: str = "/") -> None:
        import rclpy
        from std_msgs.msg import String

        from fourws_common.qos import qos_of

        self._rclpy = rclpy
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=domain_id)
        self.node = rclpy.create_node(f"fourws_run_monitor_{id(self)}", context=self.ctx,
                                      namespace=namespace, start_parameter_services=False)
        self.sim_time_s = 0.0
        self.wall_time_s: float | None = None  # the plant's, from its first answered state
        self.ended_wall: float | None = None
        self.status: dict = {}
        self.node.create_subscription(String, RUN_STATUS.ros_name, self._on_status,
                                      qos_of(RUN_STATUS))
        from rclpy.experimental import EventsExecutor

        self.ex = EventsExecutor(context=self.ctx)
        self.ex.add_node(self.node)

    def _on_status(self, msg) -> None:
        try:
            status = json.loads(msg.data)
        except ValueError:
            return
        if not isinstance(status, dict):
            return
        self.status = status
        sim, wall = status.get("sim_time_s"), status.get("wall_time_s")
        if isinstance(sim, int | float):
            self.sim_time_s = float(sim)
        if isinstance(wall, int | float):
            self.wall_time_s = float(wall)
        if status.get("state") == "ended" and self.ended_wall is None:
            self.ended_wall = time.monotonic()

    def spin(self, timeout_s: float) -> None:
        self.ex.spin_once(timeout_sec=timeout_s)

    def close(self) -> None:
        self.ex.shutdown()
        self.node.destroy_node()
        self._rclpy.try_shutdown(context=self.ctx)


def run_graph(scenario: str, controller: str, out_dir: Path, *, mode: str = "lockstep",
              record: bool = True, progress: bool = True, timeout_s: float = 1800.0,
              extra_plant: dict | None = None, compose: str = "none",
              use_sim_time: bool = False, condition: Condition = IDEAL,
              namespace: str = "", domain_id: int | None = None,
              via_adapter: bool = False, stream=sys.stderr) -> RunOutcome:
    """Run one scenario over topics; the bag goes to ``out_dir/bag``. Returns the outcome.

    ``namespace``, ``via_adapter``: as in :func:`graph_specs`; ``domain_id``: run in this
    ROS domain (default: a free one of this host, leased for the run)."""
    bag_dir = out_dir / "bag" if record else None
    status_file = out_dir / "logs" / "plant_status.json"
    with contextlib.suppress(FileNotFoundError):
        status_file.unlink()
    specs = graph_specs(scenario, controller, bag_dir, mode, extra_plant, compose,
                        status_file=status_file, use_sim_time=use_sim_time,
                        condition=condition, namespace=namespace, via_adapter=via_adapter)
    plant = next(s.name for s in specs if "plant_node" in s.graph_names)  # its process
    # The run's own participants (the monitor, the supervisor's graph probe) discover the
    # nodes with the nodes' Fast DDS profiles (supervisor.dds_environment); no effect if this
    # process has used DDS before (Fast DDS reads the file once).
    os.environ.update(dds_environment())
    lease = DomainLease() if domain_id is None else None
    domain = lease.domain_id if lease is not None else int(domain_id)
    sup = Supervisor(specs, domain, out_dir / "logs")
    monitor = None
    t0 = time.monotonic()
    try:
        # Wall time and the real-time factor are the plant's own (its status): from its
        # first answered state to its end, start-up excluded. t0 only bounds the duration.
        monitor = _Monitor(domain, normalise_namespace(namespace))
        sup.start(timeout_s=60.0)
        t0 = time.monotonic()
        last_print = 0.0
        plant_proc = sup.procs[plant]
        while True:
            monitor.spin(0.05)
            rc = plant_proc.popen.poll()
            if rc is not None:
                if rc not in plant_proc.spec.end_codes:
                    raise NodeDied(sup.describe(plant), rc, plant_proc.last_lines())
                break
            sup.check()  # a death of another node; a normal end (exit 0) is not one
            stopped = [n for n in sup.ended() if n != plant]
            if stopped:  # a controller or the recorder stopped from outside: no crash,
                raise SupervisorError(  # but the run cannot go on
                    f"{', '.join(sup.describe(n) for n in stopped)} stopped (exit 0) before "
                    "the run ended")
            now = time.monotonic()
            if now - t0 > timeout_s:
                raise SupervisorError(f"run did not end within {timeout_s:.0f} s of wall time")
            if progress and now - last_print > 0.5:
                last_print = now
                wall = monitor.wall_time_s or 0.0
                rtf = monitor.sim_time_s / wall if wall > 0.0 else 0.0
                stream.write(f"\r  {controller} on {scenario}: t_sim = {monitor.sim_time_s:6.2f} s"
                             f"  wall {wall:6.1f} s  RTF {rtf:4.1f}   ")
                stream.flush()
        outcome = _ended_outcome(rc, read_status_file(status_file), time.monotonic() - t0)
    except NodeDied as exc:
        outcome = RunOutcome(False, str(exc).splitlines()[0], time.monotonic() - t0,
                             monitor.sim_time_s if monitor else 0.0, 0, exc.name,
                             exit_code=exc.returncode, died_error=exc.last_error)
        stream.write(f"\n{exc}\n")
    except KeyboardInterrupt:
        outcome = RunOutcome(False, "interrupted by the user (Ctrl-C)", time.monotonic() - t0,
                             monitor.sim_time_s if monitor else 0.0, 0,
                             exit_code=int(ExitCode.INTERRUPTED))
    except SupervisorError as exc:  # the graph never came up, or the run never ended
        outcome = RunOutcome(False, str(exc), time.monotonic() - t0,
                             monitor.sim_time_s if monitor else 0.0, 0)
        stream.write(f"\n{exc}\n")
    finally:
        if monitor is not None:
            monitor.close()
        sup.stop()
        if lease is not None:
            lease.release()
    if progress:
        stream.write("\n")
    return outcome


def _ended_outcome(exit_code: int, status: dict | None, runner_wall_s: float) -> RunOutcome:
    """The outcome of a plant that ended normally: its status file, checked against its exit
    code (the exit code alone when the file is missing)."""
    from fourws_common.exit_codes import describe

    if status is None or status.get("state") != "ended":
        return RunOutcome(False, f"plant exited with {describe(exit_code)} without a final "
                          "status (stopped before its run ended)", runner_wall_s, 0.0, 0,
                          exit_code=exit_code)
    wall = status.get("wall_time_s")
    return RunOutcome(bool(status.get("completed", False)), str(status.get("reason", "")),
                      float(wall) if isinstance(wall, int | float) else runner_wall_s,
                      float(status.get("sim_time_s", 0.0)), int(status.get("steps", 0)),
                      exit_code=exit_code, status=status)
