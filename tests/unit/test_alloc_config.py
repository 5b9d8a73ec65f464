"""allocator.yaml loads into AllocatorConfig and mirrors its defaults; bad values name the
key; the cores of fourws_torque_alloc import nothing from ROS."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml
from params_helpers import with_car

from fourws_common.params import from_mapping, load_ros_params_yaml
from fourws_common.resources import config_dir
from fourws_torque_alloc.core.allocation import AllocatorConfig

YAML = config_dir("fourws_torque_alloc") / "allocator.yaml"
NODE = "/**/allocator_node"
# Parameters that belong to the node wrapper, not to the core (allocator_node.py).
NODE_ONLY = {"sync", "use_sim_time"}


def core_values(path: Path) -> dict:
    values = load_ros_params_yaml(str(path), NODE)
    return with_car("allocator_node", {k: v for k, v in values.items() if k not in NODE_ONLY})


def test_yaml_loads_and_mirrors_the_defaults():
    values = core_values(YAML)
    assert set(values) == {f.name for f in dataclasses.fields(AllocatorConfig)}
    assert from_mapping(AllocatorConfig, values) == AllocatorConfig()


def test_vehicle_values():
    cfg = from_mapping(AllocatorConfig, core_values(YAML))
    assert (cfg.track_width_m, cfg.wheel_radius_m, cfg.motor_torque_max_nm) == (1.30, 0.27, 500.0)


@pytest.mark.parametrize(
    ("key", "value"),
    [("method", "magic"), ("track_width_m", 0.0), ("wheel_radius_m", -0.27),
     ("motor_torque_max_nm", float("inf")), ("priority", "speed"), ("min_fz_n", -1.0),
     ("friction_circle", "yes"), ("bounded_solver", "cvxpy"), ("demand_sanity_factor", 0.5)],
)
def test_bad_value_raises_naming_the_key(tmp_path, key, value):
    data = yaml.safe_load(YAML.read_text(encoding="utf-8"))
    data[NODE]["ros__parameters"][key] = value
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    with pytest.raises(ValueError, match=key):
        from_mapping(AllocatorConfig, core_values(path))
