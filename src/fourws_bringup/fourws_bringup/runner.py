"""One closed-loop run over real topics: start the graph, record it, stop it, score it.

``run(scenario, controller, out_dir)`` starts plant, MPC, speed PID, allocator and recorder
as separate processes with the supervisor (their package YAML plus the controller preset as
``--params-file``), shows simulated time as it goes, waits for the plant to end the scenario,
stops the graph cleanly and writes ``out_dir/metrics.json`` computed from the recorded bag
alone (the same code as ``fourws report``) plus ``out_dir/plots/``. A node that dies stops
the run; the bag is kept and metrics.json says which node died.
"""

from __future__ import annotations

import json
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from fourws_common.resources import config_dir

from .supervisor import DomainLease, NodeDied, NodeSpec, Supervisor, SupervisorError

CONTROLLERS = ("mpc_fws", "mpc_4ws", "improved", "ampc_4ws", "ampc_4ws_dyc")
RECORDER_NICE = 10  # niceness added to the recorder process
#: Process layouts of a run: container process name and the nodes it hosts (None: one
#: process per node). The recorder is never composed: it is off the control chain.
COMPOSE_LAYOUTS: dict[str, tuple[str, tuple[str, ...]] | None] = {
    "none": None,
    "control": ("control_container", ("mpc_node", "speed_pid_node", "allocator_node")),
    "all": ("node_container", ("plant_node", "mpc_node", "speed_pid_node", "allocator_node")),
}


class RunError(RuntimeError):
    """A run could not be started (bad arguments, existing output, unknown preset)."""


def controller_preset(name_or_path: str) -> Path:
    """Path of a controller preset: a name in fourws_bringup/config/controllers or a file
    (:func:`fourws_bringup.core.closed_loop.controller_preset_path`), as a ``RunError``."""
    from .core.closed_loop import controller_preset_path

    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") and not p.is_file():
        raise RunError(f"controller preset file not found: {p}")
    try:
        return controller_preset_path(name_or_path).resolve()
    except ValueError as exc:
        raise RunError(f"unknown controller '{name_or_path}': {exc}") from None


def scenario_arg(name_or_path: str) -> str:
    """A scenario name stays a name; a YAML path becomes absolute for the plant process."""
    p = Path(name_or_path)
    return str(p.resolve()) if p.suffix in (".yaml", ".yml") else name_or_path


def prepare_out_dir(out_dir: Path, force: bool) -> None:
    """Refuse to overwrite an existing, non-empty output folder unless ``force``."""
    if out_dir.exists() and any(out_dir.iterdir()):
        if not force:
            raise RunError(f"output folder {out_dir} exists and is not empty; "
                           "use --force to overwrite it")
        shutil.rmtree(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)


def graph_specs(scenario: str, controller: str, bag_dir: Path | None, mode: str = "lockstep",
                extra_plant: dict | None = None, compose: str = "none") -> list[NodeSpec]:
    """The node list of a run: every node with its package YAML and the controller preset.

    ``compose`` (:data:`COMPOSE_LAYOUTS`) picks the processes: ``none``, one per node;
    ``control``, the MPC, speed PID and allocator in one container process; ``all``, the plant
    too. Same nodes, parameters and topics in every layout (:mod:`fourws_bringup.container`);
    the recorder always has a process of its own.
    """
    if compose not in COMPOSE_LAYOUTS:
        raise RunError(f"compose layout '{compose}' is not one of {sorted(COMPOSE_LAYOUTS)}")
    preset = str(controller_preset(controller))
    subscribers = 3 + (1 if bag_dir is not None else 0)
    plant_params = {"scenario": scenario_arg(scenario), "mode": mode,
                    "wait_for_subscribers": subscribers if mode == "lockstep" else 0}
    plant_params.update(extra_plant or {})
    sync = "lockstep" if mode == "lockstep" else "latest"
    specs = [
        NodeSpec("plant_node", "fourws_sim", "plant_node",
                 params_files=[str(config_dir("fourws_sim") / "plant.yaml")],
                 parameters=plant_params),
        NodeSpec("mpc_node", "fourws_mpc", "mpc_node",
                 params_files=[str(config_dir("fourws_mpc") / "mpc.yaml"), preset]),
        NodeSpec("speed_pid_node", "fourws_torque_alloc", "speed_pid_node",
                 params_files=[str(config_dir("fourws_torque_alloc") / "speed_pid.yaml")]),
        NodeSpec("allocator_node", "fourws_torque_alloc", "allocator_node",
                 params_files=[str(config_dir("fourws_torque_alloc") / "allocator.yaml"),
                               preset], parameters={"sync": sync}),
    ]
    layout = COMPOSE_LAYOUTS[compose]
    if layout is not None:
        name, hosted = layout
        inside = [s for s in specs if s.name in hosted]
        specs = [s for s in specs if s.name not in hosted] + [NodeSpec.compose(name, inside)]
    if bag_dir is not None:
        # The recorder is off the control chain (it buffers and writes chunks), so it yields
        # the CPU to the nodes the next step waits on: on 2 cores this cut the median step
        # time by about 10 % (docs/architecture.md, "Timing").
        specs.append(NodeSpec("recorder_node", "fourws_bringup", "recorder_node",
                              params_files=[str(config_dir("fourws_bringup") / "recorder.yaml")],
                              parameters={"output_dir": str(bag_dir),
                                          "start_gate_topic": "/vehicle/state"},
                              nice=RECORDER_NICE))
    return specs


@dataclass
class RunOutcome:
    completed: bool
    reason: str
    wall_time_s: float
    sim_time_s: float
    steps: int
    died: str | None = None


class _Monitor:
    """A small rclpy node in the run's domain that reads the plant's /run/status: progress
    from its heartbeats, the end and the plant's own wall time from its last message. It
    takes no per-step topic, so watching a run costs the graph nothing per step."""

    def __init__(self, domain_id: int) -> None:
        import rclpy
        from std_msgs.msg import String

        from fourws_common.qos import LATCHED_QOS

        self._rclpy = rclpy
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=domain_id)
        self.node = rclpy.create_node(f"fourws_run_monitor_{id(self)}", context=self.ctx,
                                      start_parameter_services=False)
        self.sim_time_s = 0.0
        self.wall_time_s: float | None = None  # the plant's, from its first answered state
        self.ended_wall: float | None = None
        self.status: dict = {}
        self.node.create_subscription(String, "/run/status", self._on_status, LATCHED_QOS)
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
              stream=sys.stderr) -> RunOutcome:
    """Run one scenario over topics; the bag goes to ``out_dir/bag``. Returns the outcome."""
    bag_dir = out_dir / "bag" if record else None
    specs = graph_specs(scenario, controller, bag_dir, mode, extra_plant, compose)
    plant = next(s.name for s in specs if "plant_node" in s.graph_names)  # its process
    lease = DomainLease()
    sup = Supervisor(specs, lease.domain_id, out_dir / "logs")
    monitor = None
    died = None
    t0 = time.monotonic()
    try:
        # Wall time and the real-time factor are the plant's own (/run/status): from its
        # first state to its end, start-up excluded. t0 only bounds the run's duration.
        monitor = _Monitor(lease.domain_id)
        sup.start(timeout_s=60.0)
        t0 = time.monotonic()
        last_print = 0.0
        while True:
            monitor.spin(0.05)
            exited = sup.exited()
            if plant in exited:
                if exited[plant] != 0:
                    raise NodeDied(sup.describe(plant), exited[plant],
                                   sup.procs[plant].last_lines())
                break
            sup.check()
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
        plant_exit = time.monotonic()
        for _ in range(20):  # the final status is latched; give it a moment to arrive
            if monitor.status.get("state") == "ended":
                break
            monitor.spin(0.05)
        st = monitor.status
        wall = monitor.wall_time_s or max((monitor.ended_wall or plant_exit) - t0, 1e-3)
        outcome = RunOutcome(bool(st.get("completed", False)),
                             str(st.get("reason", "plant ended without a status")), wall,
                             float(st.get("sim_time_s", monitor.sim_time_s)),
                             int(st.get("steps", 0)))
    except NodeDied as exc:
        died = exc.name
        outcome = RunOutcome(False, str(exc).splitlines()[0], time.monotonic() - t0,
                             monitor.sim_time_s if monitor else 0.0, 0, died)
        stream.write(f"\n{exc}\n")
    except KeyboardInterrupt:
        outcome = RunOutcome(False, "interrupted by the user (Ctrl-C)", time.monotonic() - t0,
                             monitor.sim_time_s if monitor else 0.0, 0)
    finally:
        if monitor is not None:
            monitor.close()
        sup.stop()
        lease.release()
    if progress:
        stream.write("\n")
    return outcome
