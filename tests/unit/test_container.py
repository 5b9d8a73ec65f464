"""The node container's command line and the supervisor's composed node spec (no DDS)."""

from __future__ import annotations

import dataclasses

import pytest

from fourws_bringup.container import NODES, node_factories, parse_nodes
from fourws_bringup.supervisor import NodeSpec


def _specs() -> list[NodeSpec]:
    return [
        NodeSpec("mpc_node", "fourws_mpc", "mpc_node", params_files=["mpc.yaml", "preset.yaml"]),
        NodeSpec("speed_pid_node", "fourws_torque_alloc", "speed_pid_node",
                 params_files=["pid.yaml"]),
        NodeSpec("allocator_node", "fourws_torque_alloc", "allocator_node",
                 params_files=["alloc.yaml", "preset.yaml"], parameters={"sync": "lockstep"}),
    ]


def test_composed_spec_gives_each_node_exactly_its_own_parameters():
    spec = NodeSpec.compose("control_container", _specs())
    cmd = spec.command()
    assert spec.graph_names == ("mpc_node", "speed_pid_node", "allocator_node")
    assert cmd[1:3] == ["--nodes", "mpc_node,speed_pid_node,allocator_node"]
    assert not any(a.startswith("__node:=") for a in cmd), "a container must not rename nodes"
    files = [cmd[i + 1] for i, a in enumerate(cmd) if a == "--params-file"]
    assert sorted(files) == ["alloc.yaml", "mpc.yaml", "pid.yaml", "preset.yaml"]
    for s in _specs():  # a later file overrides: each node's own order must hold
        assert [f for f in files if f in s.params_files] == s.params_files, s.name
    rules = [cmd[i + 1] for i, a in enumerate(cmd) if a == "-p"]
    assert rules == ["allocator_node:sync:=lockstep"]


def test_parameter_files_whose_orders_contradict_cannot_be_composed():
    a = NodeSpec("mpc_node", "fourws_mpc", "mpc_node", params_files=["x.yaml", "y.yaml"])
    b = NodeSpec("allocator_node", "fourws_torque_alloc", "allocator_node",
                 params_files=["y.yaml", "x.yaml"])
    with pytest.raises(ValueError, match="contradict"):
        NodeSpec.compose("c", [a, b])


def test_a_composed_node_gets_the_preset_over_its_package_defaults(tmp_path):
    """The real files: mpc_4ws's preset sets the allocator's method to 'equal' over
    allocator.yaml's 'optimal'; the container must be given them in that order too."""
    from fourws_bringup.graph import graph_specs

    for layout in ("control", "all"):
        (box,) = [s for s in graph_specs("dlc_60_mu05", "mpc_4ws", None, compose=layout)
                  if s.hosts]
        files = box.params_files
        alloc = next(f for f in files if f.endswith("allocator.yaml"))
        preset = next(f for f in files if f.endswith("mpc_4ws.yaml"))
        mpc = next(f for f in files if f.endswith("mpc.yaml"))
        assert files.index(alloc) < files.index(preset) and files.index(mpc) < files.index(preset)


def test_a_plain_spec_keeps_its_node_name_remap():
    spec = _specs()[0]
    assert spec.graph_names == ("mpc_node",)
    assert "__node:=mpc_node" in spec.command()


def test_compose_refuses_what_a_container_cannot_host():
    with pytest.raises(ValueError, match="at least one node"):
        NodeSpec.compose("c", [])
    # a remapping applies to the whole process: only one every hosted node shares
    odd = NodeSpec("mpc_node", "fourws_mpc", "mpc_node", remappings={"/a": "/b"})
    with pytest.raises(ValueError, match="mpc_node"):
        NodeSpec.compose("c", [*_specs()[:1], odd])
    shared = [dataclasses.replace(s, remappings={"/clock": "/car1/clock"}, namespace="car1")
              for s in _specs()]
    both = NodeSpec.compose("c", shared)
    assert both.remappings == {"/clock": "/car1/clock"} and both.namespace == "/car1"
    assert "/clock:=/car1/clock" in both.command() and "__ns:=/car1" in both.command()
    with pytest.raises(ValueError, match="namespace"):
        NodeSpec.compose("c", [shared[0], dataclasses.replace(shared[1], namespace="car2")])
    inner = NodeSpec.compose("inner", _specs()[:1])
    with pytest.raises(ValueError, match="inner"):
        NodeSpec.compose("outer", [inner])


def test_container_arguments_name_the_nodes_or_say_what_is_wrong():
    assert parse_nodes(["--nodes", "mpc_node,allocator_node"]) == ["mpc_node", "allocator_node"]
    assert parse_nodes(["--nodes=plant_node"]) == ["plant_node"]
    with pytest.raises(ValueError, match="--nodes is missing"):
        parse_nodes([])
    with pytest.raises(ValueError, match="unknown node"):
        node_factories(["mpc_node", "nav2_node"])
    with pytest.raises(ValueError, match="twice"):
        node_factories(["mpc_node", "mpc_node"])
    with pytest.raises(ValueError, match="no nodes"):
        node_factories([])


def test_every_hostable_node_is_the_class_its_own_executable_runs():
    import importlib

    for name, factory in zip(NODES, node_factories(list(NODES)), strict=True):
        module = importlib.import_module(NODES[name].split(":")[0])
        names = module.main.__code__.co_names
        assert "run_node" in names and factory.__name__ in names, (name, names)


@pytest.mark.parametrize(("layout", "processes"), [
    ("none", {"plant_node", "mpc_node", "speed_pid_node", "allocator_node", "recorder_node"}),
    ("control", {"plant_node", "control_container", "recorder_node"}),
    ("all", {"node_container", "recorder_node"}),
])
def test_every_layout_hosts_every_node_once_and_the_recorder_alone(tmp_path, layout, processes):
    from fourws_bringup.graph import graph_specs

    specs = graph_specs("dlc_60_mu05", "improved", tmp_path / "bag", compose=layout)
    assert {s.name for s in specs} == processes
    names = [n for s in specs for n in s.graph_names]
    assert sorted(names) == sorted(["plant_node", "mpc_node", "speed_pid_node",
                                    "allocator_node", "recorder_node"])
    recorder = next(s for s in specs if s.name == "recorder_node")
    assert recorder.hosts == () and recorder.nice > 0
    rules = [c[i + 1] for c in (s.command() for s in specs) for i, a in enumerate(c) if a == "-p"]
    qualify = "" if layout == "none" else "allocator_node:"
    assert f"{qualify}sync:=lockstep" in rules, rules
    for spec in (s for s in specs if s.hosts):
        cmd = spec.command()
        hosted_rules = [cmd[i + 1] for i, a in enumerate(cmd) if a == "-p"]
        assert all(r.split(":")[0] in spec.hosts for r in hosted_rules), hosted_rules


def test_an_unknown_layout_is_a_clear_error(tmp_path):
    from fourws_bringup.graph import graph_specs
    from fourws_bringup.outputs import RunError

    with pytest.raises(RunError, match="'some'"):
        graph_specs("dlc_60_mu05", "improved", None, compose="some")
