"""The node table of a run (docs/graph.md, "Runs", "Launch").

Which processes, with which params files, parameters, namespaces and clocks (``graph_specs``,
``control_specs``); used by ``fourws run``, the launch files and the tests, so they start the
same graph.
"""

from __future__ import annotations

from pathlib import Path

from fourws_common.exit_codes import RUN_END_CODES
from fourws_common.topics import (
    CLOCK,
    VEHICLE_GROUND_TRUTH,
    VEHICLE_IMU,
    VEHICLE_JOINT_STATES,
    VEHICLE_STATE,
)

from .core.conditions import IDEAL, Condition, node_parameters
from .core.configs import controller_preset_path, node_values, params_files
from .outputs import RunError
from .supervisor import NodeSpec, normalise_namespace

RECORDER_NICE = 10  # niceness added to the recorder process
#: Process layouts of a run: container process name and the nodes it hosts (None: one
#: process per node). The recorder is never composed: it is off the control chain.
COMPOSE_LAYOUTS: dict[str, tuple[str, tuple[str, ...]] | None] = {
    "none": None,
    "control": ("control_container", ("mpc_node", "speed_pid_node", "allocator_node")),
    "all": ("node_container", ("plant_node", "mpc_node", "speed_pid_node", "allocator_node")),
}


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
        # time by about 10 % (docs/graph.md, "Timing").
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
