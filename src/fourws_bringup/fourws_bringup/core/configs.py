"""Where every node's parameters come from: package params files and controller presets.

The one owner of configuration loading (docs/graph.md, "Configuration"). A node's parameters
are its package params file (:data:`PACKAGE_FILES`) and, for the nodes a controller preset
configures (:data:`PRESET_NODES`), the preset ``fourws_bringup/config/controllers/<name>.yaml``
after it, so the preset overrides the package file. :func:`params_files` gives that list in
that order: the graph passes it as ``--params-file`` arguments (``graph.graph_specs``), and the
in-process loop, the report and the tools merge the same files in the same order
(:func:`node_values`, :func:`load_mpc_config`, ...), so the two cannot take a parameter
differently.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fourws_common.input_guard import InputConfig
from fourws_common.params import from_mapping, load_ros_params_yaml, read_yaml_file
from fourws_common.resources import config_dir, named_yaml
from fourws_common.vehicle_info import load_vehicle_info, node_vehicle_values

if TYPE_CHECKING:  # imported where loaded: the MPC's pulls in numba, osqp and scipy (~0.5 s
    # of every `fourws` start, which mostly only needs the file lists)
    from fourws_mpc.core.config import MpcConfig
    from fourws_torque_alloc.core.allocation import AllocatorConfig
    from fourws_torque_alloc.core.pid import SpeedPidConfig

#: node name -> (package, params file in its config/)
PACKAGE_FILES: dict[str, tuple[str, str]] = {
    "plant_node": ("fourws_sim", "plant.yaml"),
    "mpc_node": ("fourws_mpc", "mpc.yaml"),
    "speed_pid_node": ("fourws_torque_alloc", "speed_pid.yaml"),
    "allocator_node": ("fourws_torque_alloc", "allocator.yaml"),
    "recorder_node": ("fourws_bringup", "recorder.yaml"),
    "replay_node": ("fourws_bringup", "replay.yaml"),
    "adapter_node": ("fourws_bringup", "adapter.yaml"),
}
#: nodes whose sections a controller preset holds
PRESET_NODES = ("mpc_node", "allocator_node")


def controllers_dir() -> Path:
    """``fourws_bringup/config/controllers``."""
    return config_dir("fourws_bringup") / "controllers"


def list_controllers() -> list[str]:
    """Names of the shipped controller presets."""
    return sorted(p.stem for p in controllers_dir().glob("*.yaml"))


def is_yaml_path(entry: str) -> bool:
    """Whether a spec's or a command's scenario or controller entry names a file (``.yaml``,
    ``.yml``) rather than a shipped name: the one rule."""
    return str(entry).endswith((".yaml", ".yml"))


def beside(spec_path: str | Path, entry: Any) -> str:
    """A spec's scenario or controller entry: a relative ``.yaml`` path is relative to the
    spec's folder (``..`` collapsed as text: a spec folder reached through a symlink is
    taken as written); a name (or an absolute path) is kept as it is."""
    s = str(entry)
    if is_yaml_path(s) and not Path(s).is_absolute():
        return os.path.normpath(Path(spec_path).parent / s)
    return s


def preset_label(entry: str) -> str:
    """A controller entry as reports name it: a preset file by its stem, a name as it is."""
    return Path(entry).stem if is_yaml_path(entry) else str(entry)


def controller_preset_path(name_or_path: str) -> Path:
    """``controllers/<name>.yaml`` of fourws_bringup, or the given file; ``ValueError``
    naming the known presets otherwise."""
    return named_yaml(name_or_path, controllers_dir(), "controller preset")


def package_file(node: str) -> Path:
    """The package params file of ``node``."""
    package, name = PACKAGE_FILES[node]
    return config_dir(package) / name


def check_preset(name_or_path: str) -> None:
    """Refuse a controller preset that a node would refuse, before any node starts: a file
    that is not YAML or not a mapping, a section for another node than
    :data:`PRESET_NODES`, no ``mpc_node`` parameters, or a key, type or value the nodes'
    configs reject (``ValueError``, one line naming the file and the key)."""
    path = controller_preset_path(name_or_path)
    data = read_yaml_file(path) or {}
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected node sections (/**/mpc_node: ros__parameters: "
                         f"...), got {type(data).__name__}")
    for key, section in data.items():
        node = str(key).rsplit("/", 1)[-1]
        if node not in PRESET_NODES:
            raise ValueError(f"{path}: section '{key}' is not one of the preset's nodes "
                             f"({', '.join(PRESET_NODES)})")
        if not isinstance(section, dict) or set(section) != {"ros__parameters"}:
            raise ValueError(f"{path}: section '{key}' must hold ros__parameters only")
    if not load_ros_params_yaml(str(path), "mpc_node"):
        raise ValueError(f"{path}: no mpc_node parameters (an empty preset would run the "
                         "defaults under this file's name)")
    for load in (load_mpc_config, load_allocator_config):
        try:
            load(str(path))
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None


def params_files(node: str, controller: str | None = None) -> list[Path]:
    """The params files of ``node`` in the order they apply: the package file, then the
    controller preset for :data:`PRESET_NODES` (when ``controller`` is given)."""
    files = [package_file(node)]
    if controller is not None and node in PRESET_NODES:
        files.append(controller_preset_path(controller).resolve())
    return files


def node_values(node: str, controller: str | None = None,
                overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """``node``'s parameters as the node takes them: the car's values
    (:func:`fourws_common.vehicle_info.node_vehicle_values`; the car of ``overrides``'
    ``vehicle_file``, default the paper's), then :func:`params_files` (later files win), then
    ``overrides``."""
    overrides = dict(overrides or {})
    car = load_vehicle_info(overrides.get("vehicle_file") or None)
    values: dict[str, Any] = node_vehicle_values(node, car)
    for path in params_files(node, controller):
        values.update(load_ros_params_yaml(str(path), node))
    values.update(overrides)
    return values


def core_values(values: dict[str, Any]) -> dict[str, Any]:
    """A node's parameters without its node-level keys (:class:`InputConfig`'s and
    ``vehicle_file``), i.e. the keys of its core's config dataclass."""
    node_keys = {f.name for f in dataclasses.fields(InputConfig)} | {"vehicle_file"}
    return {k: v for k, v in values.items() if k not in node_keys}


def load_mpc_config(controller: str, overrides: dict[str, Any] | None = None) -> MpcConfig:
    """mpc.yaml with the preset's ``mpc_node`` section (and ``overrides``) merged over it."""
    from fourws_mpc.core.config import MpcConfig

    return MpcConfig.from_mapping(core_values(node_values("mpc_node", controller, overrides)))


def load_allocator_config(controller: str | None,
                          overrides: dict[str, Any] | None = None) -> AllocatorConfig:
    """allocator.yaml with the preset's ``allocator_node`` section (the file alone for
    ``None``) and ``overrides`` merged over it."""
    from fourws_torque_alloc.core.allocation import AllocatorConfig

    return from_mapping(AllocatorConfig, core_values(node_values("allocator_node",
                                                                 controller, overrides)))


def load_pid_config(overrides: dict[str, Any] | None = None) -> SpeedPidConfig:
    """speed_pid.yaml (and ``overrides``) over the car's values."""
    from fourws_torque_alloc.core.pid import SpeedPidConfig

    return from_mapping(SpeedPidConfig, core_values(node_values("speed_pid_node",
                                                                overrides=overrides)))


def plant_values() -> dict[str, Any]:
    """plant.yaml's ``plant_node`` parameters."""
    return node_values("plant_node")
