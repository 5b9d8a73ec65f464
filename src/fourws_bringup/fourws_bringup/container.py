"""Node container: several fourws nodes in one process, as a ROS 2 component container would.

    container --nodes mpc_node,speed_pid_node,allocator_node --ros-args \\
        --params-file src/fourws_mpc/config/mpc.yaml ... -p allocator_node:sync:=lockstep

Each hosted node is the same class its own executable runs, with its own name, parameters
(YAML sections keyed by node name; ``-p node:name:=value`` for one node) and topics. They
share the process, the DDS participant and one executor thread, so the messages between them
(state → MPC → allocator, drive command → allocator) take no inter-process hop and wake no
other process. rclpy has no component container of its own; this is the pattern of
ros2/examples' ``examples_rclpy_executors/composed.py`` behind a command line.

``fourws run --compose control`` hosts the MPC, the speed PID and the allocator here (the plant
stays a process of its own, as a real car's interface would); ``--compose all`` hosts the
plant too (docs/graph.md, "Processes"). The recorder always keeps its own process. Results are
the same bit for bit (lockstep answers are keyed by the state stamp); only the timing changes.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable

from rclpy.node import Node
from rclpy.utilities import remove_ros_args

from fourws_common.node_main import run_nodes

#: The nodes a container can host: graph name → ``module:Class``.
NODES: dict[str, str] = {
    "plant_node": "fourws_sim.plant_node:PlantNode",
    "mpc_node": "fourws_mpc.mpc_node:MpcNode",
    "speed_pid_node": "fourws_torque_alloc.speed_pid_node:SpeedPidNode",
    "allocator_node": "fourws_torque_alloc.allocator_node:AllocatorNode",
}

USAGE = f"usage: container --nodes NAME[,NAME...] [--ros-args ...]; NAME in {sorted(NODES)}"


def node_factories(names: list[str]) -> list[Callable[[], Node]]:
    """The node classes for ``names``; ValueError naming an unknown or repeated node."""
    if not names:
        raise ValueError(f"no nodes given; {USAGE}")
    unknown = [n for n in names if n not in NODES]
    if unknown:
        raise ValueError(f"unknown node(s) {unknown}; {USAGE}")
    if len(set(names)) != len(names):
        raise ValueError(f"a node is listed twice: {names}")
    out = []
    for name in names:
        module, cls = NODES[name].split(":")
        out.append(getattr(importlib.import_module(module), cls))
    return out


def parse_nodes(argv: list[str]) -> list[str]:
    """The ``--nodes a,b`` (or ``--nodes=a,b``) list from the non-ROS arguments."""
    for i, arg in enumerate(argv):
        if arg == "--nodes" and i + 1 < len(argv):
            return [n for n in argv[i + 1].split(",") if n]
        if arg.startswith("--nodes="):
            return [n for n in arg.split("=", 1)[1].split(",") if n]
    raise ValueError(f"--nodes is missing; {USAGE}")


def main(args: list[str] | None = None) -> int:
    argv = list(sys.argv if args is None else args)
    try:
        factories = node_factories(parse_nodes(remove_ros_args(argv)[1:]))
    except ValueError as exc:
        print(f"[fatal] {exc}", file=sys.stderr, flush=True)
        return 2
    return run_nodes(factories, argv)


if __name__ == "__main__":
    raise SystemExit(main())
