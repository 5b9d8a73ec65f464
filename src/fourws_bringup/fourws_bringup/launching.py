"""Launch descriptions of fourws from the node table of ``fourws run`` (docs/graph.md, "Launch").

``ros2 launch fourws_bringup fourws.launch.py`` and ``fourws run`` share that table
(:func:`fourws_bringup.graph.graph_specs` and :func:`~fourws_bringup.graph.control_specs`),
so the two cannot drift: the same nodes, parameter files, parameters, namespaces and process
layouts.

Each :class:`~fourws_bringup.supervisor.NodeSpec` becomes one ``launch_ros.actions.Node``
with the spec's own ``--ros-args`` (:meth:`NodeSpec.ros_arguments`). ``fourws.launch.py``
ends when the plant process ends: its exit status is logged with its meaning
(:mod:`fourws_common.exit_codes`) and the graph is shut down (SIGINT to every node, so the
recorder closes its bag). ``ros2 launch`` itself can only exit 0 or 1: it exits 0 when the
plant completed the scenario (exit 0) and 1 for any other end (aborted 3, timeout 4, a
crash), with the plant's code in the last error line.

Only ``ros2 launch`` imports this module (it needs the ``launch`` and ``launch_ros``
packages of a ROS install); nothing else in fourws does.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from launch import LaunchContext, LaunchDescription
from launch.actions import (
    DeclareLaunchArgument,
    EmitEvent,
    LogInfo,
    OpaqueFunction,
    RegisterEventHandler,
    SetEnvironmentVariable,
)
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from fourws_common.exit_codes import describe
from fourws_common.vehicle_info import list_vehicles

from .core.conditions import IDEAL, load_condition
from .core.configs import list_controllers
from .graph import COMPOSE_LAYOUTS, control_specs, graph_specs
from .outputs import RunError
from .supervisor import NodeSpec, dds_environment

TRUE, FALSE = ("true", "1", "yes", "on"), ("false", "0", "no", "off")


class LaunchArgumentError(RuntimeError):
    """A launch argument with a value fourws cannot use; the message names it."""


#: seconds before a respawned controller process starts again (``respawn:=true``)
RESPAWN_DELAY_S = 0.5


def launch_node(spec: NodeSpec, respawn: bool = False) -> Node:
    """One process of the node table as a launch action (a container keeps its nodes'
    own names; a lower CPU priority becomes a ``nice`` prefix); ``respawn``: started again
    :data:`RESPAWN_DELAY_S` after it dies."""
    return Node(package=spec.package, executable=spec.executable,
                name=None if spec.hosts else spec.name, namespace=spec.namespace,
                arguments=spec.program_arguments(), ros_arguments=spec.ros_arguments(),
                exec_name=spec.name, prefix=f"nice -n {spec.nice}" if spec.nice else None,
                output="screen", respawn=respawn,
                respawn_delay=RESPAWN_DELAY_S if respawn else None)


def _arg(context: LaunchContext, name: str) -> str:
    return LaunchConfiguration(name).perform(context).strip()


def _flag(context: LaunchContext, name: str) -> bool:
    value = _arg(context, name).lower()
    if value not in TRUE + FALSE:
        raise LaunchArgumentError(f"launch argument {name}:={value!r}: expected true or false")
    return value in TRUE


def _choice(context: LaunchContext, name: str, choices: tuple[str, ...]) -> str:
    value = _arg(context, name)
    if value not in choices:
        raise LaunchArgumentError(f"launch argument {name}:={value!r}: expected one of "
                                  f"{list(choices)}")
    return value


def _condition(context: LaunchContext) -> Any:
    name, seed = _arg(context, "condition"), _arg(context, "seed")
    if seed:
        try:
            int(seed)
        except ValueError:
            raise LaunchArgumentError(f"launch argument seed:={seed!r}: expected an "
                                      "integer") from None
        if not name:
            raise LaunchArgumentError(f"launch argument seed:={seed}: the ideal world has no "
                                      "noise to seed; give condition:= too")
    condition = IDEAL
    if name:
        try:
            condition = load_condition(name, int(seed) if seed else None)
        except (ValueError, OSError) as exc:
            raise LaunchArgumentError(f"launch argument condition:={name!r}: {exc}") from None
    vehicle = _arg(context, "vehicle")
    if vehicle:
        from fourws_common.vehicle_info import load_vehicle_info

        try:
            load_vehicle_info(vehicle)
        except ValueError as exc:
            raise LaunchArgumentError(f"launch argument vehicle:={vehicle!r}: {exc}") from None
        condition = dataclasses.replace(condition, vehicle=vehicle)
    return condition


def _scenario(context: LaunchContext, vehicle: str = "") -> str:
    """The scenario argument, checked to load on the car before any node starts."""
    from fourws_sim.core.scenario import load_scenario

    name = _arg(context, "scenario")
    try:
        load_scenario(name, vehicle=vehicle or None)
    except (ValueError, FileNotFoundError) as exc:
        raise LaunchArgumentError(f"launch argument scenario:={name!r}: {exc}") from None
    return name


def _graph(context: LaunchContext) -> list[Any]:
    mode = _choice(context, "mode", ("lockstep", "realtime"))
    compose = _choice(context, "compose", tuple(COMPOSE_LAYOUTS))
    record = _flag(context, "record")
    bag = _arg(context, "bag")
    if record and not bag:
        raise LaunchArgumentError("launch argument record:=true needs bag:=FOLDER (the bag "
                                  "folder to create)")
    if record and Path(bag).exists():
        raise LaunchArgumentError(f"launch argument bag:={bag!r}: exists already (the "
                                  "recorder creates it)")
    condition = _condition(context)
    try:
        specs = graph_specs(_scenario(context, condition.vehicle),
                            _arg(context, "controller"),
                            Path(bag).resolve() if record else None, mode, compose=compose,
                            use_sim_time=_flag(context, "use_sim_time"),
                            condition=condition, namespace=_arg(context, "namespace"))
    except (RunError, ValueError) as exc:
        raise LaunchArgumentError(str(exc)) from None
    plant = next(s.name for s in specs if "plant_node" in s.graph_names)
    respawn = _flag(context, "respawn")
    nodes = {s.name: launch_node(s, respawn and s.name != plant and "recorder" not in s.name)
             for s in specs}

    def plant_ended(event: Any, _context: LaunchContext) -> list[Any]:
        rc = int(event.returncode)
        what = f"plant_node ended with exit code {describe(rc)}"
        if rc != 0:
            # launch's only way to a non-zero exit status: an error in an event handler
            raise RuntimeError(f"{what}; the graph is shut down")
        return [LogInfo(msg=f"{what}; stopping the graph"),
                EmitEvent(event=Shutdown(reason=what))]

    return [*nodes.values(), RegisterEventHandler(OnProcessExit(
        target_action=nodes[plant], on_exit=plant_ended))]


def _controllers(context: LaunchContext) -> list[Any]:
    try:
        specs = control_specs(_arg(context, "controller"),
                              _choice(context, "sync", ("latest", "lockstep")),
                              compose=_choice(context, "compose", ("none", "control")),
                              use_sim_time=_flag(context, "use_sim_time"),
                              condition=_condition(context),
                              namespace=_arg(context, "namespace"))
    except (RunError, ValueError) as exc:
        raise LaunchArgumentError(str(exc)) from None
    return [launch_node(s, _flag(context, "respawn")) for s in specs]


def _common_arguments() -> list[Any]:
    """The arguments both launch files take, after the Fast DDS profiles every fourws node
    gets (``supervisor.dds_environment``: none if the environment names a file)."""
    return [
        *[SetEnvironmentVariable(k, v) for k, v in dds_environment().items()],
        DeclareLaunchArgument("controller", default_value="improved", description=(
            f"controller preset name ({', '.join(list_controllers())}) or a preset YAML "
            "path")),
        DeclareLaunchArgument("namespace", default_value="", description=(
            "namespace of every node and its topics; the simulation's /clock moves with it "
            "(each simulated car has its own clock), /diagnostics stays global")),
        DeclareLaunchArgument("use_sim_time", default_value="false",
                              description="every node's clock follows /clock"),
        DeclareLaunchArgument("condition", default_value="", description=(
            "the bench: a shipped condition (realistic), a condition YAML or SPEC.yaml#NAME; "
            "empty: ideal")),
        DeclareLaunchArgument("seed", default_value="", description="noise seed of the "
                              "condition (empty: the condition's, else 0; needs condition:=)"),
        DeclareLaunchArgument("vehicle", default_value="", description=(
            f"the car: a shipped car ({', '.join(list_vehicles())}) or a car file; every "
            "node reads it (empty: the paper's car)")),
        DeclareLaunchArgument("respawn", default_value="false", description=(
            "start a controller process again when it dies (the plant's safe hold bridges "
            "the gap; the plant and the recorder are never respawned)")),
    ]


def fourws_launch_description() -> LaunchDescription:
    """Plant, MPC (or lqr_ff), speed PID, allocator and optionally the recorder."""
    return LaunchDescription([
        DeclareLaunchArgument("scenario", default_value="dlc_60_mu05",
                              description="scenario name or YAML path"),
        *_common_arguments(),
        DeclareLaunchArgument("mode", default_value="lockstep", choices=["lockstep",
                                                                        "realtime"],
                              description="lockstep: each step waits for every command; "
                                          "realtime: the plant steps on a 10 ms wall timer"),
        DeclareLaunchArgument("compose", default_value="none",
                              choices=sorted(COMPOSE_LAYOUTS),
                              description="none: a process per node; control: MPC, PID and "
                                          "allocator in one container; all: the plant too"),
        DeclareLaunchArgument("record", default_value="false",
                              description="record every topic to bag:=FOLDER (MCAP)"),
        DeclareLaunchArgument("bag", default_value="",
                              description="bag folder to create when record:=true"),
        OpaqueFunction(function=_graph),
    ])


def controllers_launch_description() -> LaunchDescription:
    """The control stack alone (MPC, speed PID, allocator), for a user's own plant."""
    return LaunchDescription([
        *_common_arguments(),
        DeclareLaunchArgument("sync", default_value="latest", choices=["latest", "lockstep"],
                              description="latest: answer the newest state (a plant on its "
                                          "own clock); lockstep: answer every state"),
        DeclareLaunchArgument("compose", default_value="none", choices=["none", "control"],
                              description="control: the three nodes in one container process"),
        OpaqueFunction(function=_controllers),
    ])
