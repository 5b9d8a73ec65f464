"""speed_pid.yaml loads into SpeedPidConfig and mirrors its defaults; bad values name the key."""

from __future__ import annotations

import dataclasses

import pytest
import yaml
from params_helpers import core_keys, with_car

from fourws_common.params import from_mapping, load_ros_params_yaml
from fourws_common.resources import config_dir
from fourws_torque_alloc.core.pid import SpeedPidConfig

YAML = config_dir("fourws_torque_alloc") / "speed_pid.yaml"
NODE = "/**/speed_pid_node"




def _values(path):
    """The core's values of a params file over the car's, as the node builds them."""
    return with_car("speed_pid_node", core_keys(load_ros_params_yaml(str(path), NODE)))

def test_yaml_loads_and_mirrors_the_defaults():
    values = _values(YAML)
    assert set(values) == {f.name for f in dataclasses.fields(SpeedPidConfig)}
    assert from_mapping(SpeedPidConfig, values) == SpeedPidConfig()


def test_force_limit_is_four_motors_over_the_wheel_radius():
    cfg = from_mapping(SpeedPidConfig, _values(YAML))
    assert cfg.max_total_torque_nm == 4 * 500.0
    assert cfg.max_force_n == pytest.approx(2000.0 / 0.27)


@pytest.mark.parametrize(
    ("key", "value"),
    [("kp", -1.0), ("ki", "fast"), ("derivative_filter_tau_s", -0.1),
     ("anti_windup", "magic"), ("wheel_radius_m", 0.0), ("accel_feedforward", 1.5),
     ("max_total_torque_nm", float("nan"))],
)
def test_bad_value_raises_naming_the_key(tmp_path, key, value):
    data = yaml.safe_load(YAML.read_text(encoding="utf-8"))
    data[NODE]["ros__parameters"][key] = value
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    with pytest.raises(ValueError, match=key):
        from_mapping(SpeedPidConfig, _values(path))


def test_cross_field_rule_names_both_fields():
    with pytest.raises(ValueError, match="min_total_torque_nm, max_total_torque_nm"):
        from_mapping(SpeedPidConfig, {"min_total_torque_nm": 0.0, "max_total_torque_nm": 0.0})


def test_unknown_key_raises():
    with pytest.raises(ValueError, match="kq"):
        from_mapping(SpeedPidConfig, {"kq": 1.0})
