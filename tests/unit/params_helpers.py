"""Shared helper of the params-file tests (imported by test modules, not collected)."""

from fourws_bringup.core.configs import core_values
from fourws_common.input_guard import InputConfig
from fourws_common.params import from_mapping


def core_keys(values: dict) -> dict:
    """The core's keys of a node's params file (``configs.core_values``); checks that the
    node-level input keys (:class:`InputConfig`) hold their defaults."""
    node = {k: v for k, v in values.items() if k not in core_values(values)}
    assert from_mapping(InputConfig, node) == InputConfig()
    return core_values(values)


def with_car(node: str, values: dict) -> dict:
    """A node's core values over the values it takes from the default car
    (:func:`fourws_common.vehicle_info.node_vehicle_values`), as the node builds them."""
    from fourws_common.vehicle_info import load_vehicle_info, node_vehicle_values

    car = node_vehicle_values(node, load_vehicle_info())
    return {**car, **values}
