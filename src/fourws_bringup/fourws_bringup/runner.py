"""One closed-loop run over real topics: start the graph, record it, stop it, score it.

``run(scenario, controller, out_dir)`` starts plant, MPC, speed PID, allocator and recorder
as separate processes with the supervisor (their package YAML plus the controller preset as
``--params-file``), shows simulated time as it goes, waits for the plant to end the scenario,
stops the graph cleanly and writes ``out_dir/metrics.json`` computed from the recorded bag
alone (the same code as ``fourws report``) plus ``out_dir/plots/`` (docs/graph.md, "Runs"). A
node that dies stops the run; the bag is kept and metrics.json says which node died and its
last error line.

The outcome of a run comes from two records that do not depend on DDS timing: the plant's
exit status (:class:`fourws_common.exit_codes.ExitCode`: completed, aborted, timeout) and the
final status JSON it writes to ``logs/plant_status.json`` before it exits (docs/graph.md,
"Lifecycle and bad input"). The /run/status monitor only shows progress.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from fourws_common.exit_codes import RUN_END_CODES, ExitCode
from fourws_common.topics import (
    RUN_STATUS,
)

from .core.conditions import IDEAL, Condition
from .graph import graph_specs
from .supervisor import (
    DomainLease,
    NodeDied,
    Supervisor,
    SupervisorError,
    dds_environment,
    normalise_namespace,
)


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
              via_adapter: bool = False, stream=sys.stderr,
              on_started: Callable[[], None] | None = None) -> RunOutcome:
    """Run one scenario over topics; the bag goes to ``out_dir/bag``. Returns the outcome.

    ``namespace``, ``via_adapter``: as in :func:`graph_specs`; ``domain_id``: run in this
    ROS domain (default: a free one of this host, leased for the run); ``on_started``:
    called once every node is in the graph (the caller's work that may overlap the run)."""
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
    ended_normally = False
    t0 = time.monotonic()
    try:
        # Wall time and the real-time factor are the plant's own (its status): from its
        # first answered state to its end, start-up excluded. t0 only bounds the duration.
        monitor = _Monitor(domain, normalise_namespace(namespace))
        sup.start(timeout_s=60.0)
        if on_started is not None:
            on_started()
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
        ended_normally = True
    except NodeDied as exc:
        outcome = _died(exc, time.monotonic() - t0, monitor, stream)
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
        codes = sup.stop()
        if lease is not None:
            lease.release()
    if ended_normally:
        # A node that failed during the run (the recorder on a full disk) keeps its error
        # code through the stop: the run's outcome then, whichever exit the loop saw first.
        failed = [n for n, c in codes.items() if n != plant and c is not None and c > 0
                  and c not in sup.procs[n].spec.end_codes]
        if failed:
            proc = sup.procs[failed[0]]
            outcome = _died(NodeDied(sup.describe(failed[0]), codes[failed[0]],
                                     proc.last_lines()), outcome.wall_time_s, monitor, stream)
    if progress:
        stream.write("\n")
    return outcome


def _died(exc: NodeDied, wall_s: float, monitor, stream) -> RunOutcome:
    """The outcome of a run in which a node other than the plant died (said on ``stream``)."""
    stream.write(f"\n{exc}\n")
    return RunOutcome(False, str(exc).splitlines()[0], wall_s,
                      monitor.sim_time_s if monitor else 0.0, 0, exc.name,
                      exit_code=exc.returncode, died_error=exc.last_error)


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
