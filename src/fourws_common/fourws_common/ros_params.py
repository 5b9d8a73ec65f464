"""Declare a core's config dataclass as ROS parameters with descriptors and ranges.

Values come from the package YAML (``--params-file``); types, ranges and descriptions come
from the dataclass field metadata (:func:`fourws_common.params.param`). Runtime changes go
through :meth:`ParamBinding.on_set`, which validates the whole new config (field rules and
cross-field rules) and swaps it in at once, or rejects the change with the reason; a change
that leaves the config equal (a value set to what it already is, a ``ros2 param load`` of the
node's own dump) is accepted and changes nothing (``on_change`` is not called).

A params-file value of the wrong type is an error naming the key (an integer is accepted for
a float field: ``3`` means ``3.0``); :func:`check_overrides` makes an unknown key one too
(docs/graph.md, "Lifecycle and bad input").
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, Generic, TypeVar

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter

from fourws_common.params import check_field

T = TypeVar("T")


def _descriptor(f: dataclasses.Field) -> ParameterDescriptor:
    meta = f.metadata
    unit = meta.get("unit") or ""
    text = meta.get("description", "") + (f" [{unit}]" if unit else "")
    choices = meta.get("choices")
    if choices:
        text += f" one of {list(choices)}"
    desc = ParameterDescriptor(description=text)
    if choices:  # shown by ``ros2 param describe`` as "Constraints:"
        desc.additional_constraints = "one of: " + ", ".join(str(c) for c in choices)
    lo, hi = meta.get("lo"), meta.get("hi")
    if lo is not None and hi is not None and not isinstance(f.default, tuple | bool):
        if isinstance(f.default, int):
            desc.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
        elif isinstance(f.default, float):
            desc.floating_point_range = [
                FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)
            ]
    return desc


def _ros_default(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


class ParamBinding(Generic[T]):
    """Binds a frozen config dataclass to a node's parameters.

    ``binding.config`` is always a complete, validated config. ``on_change`` (optional) is
    called with the new config after a runtime change has been accepted. ``defaults``
    (optional) replace the dataclass defaults of the fields it names (the car's values,
    :func:`vehicle_defaults`); a params file or the command line still wins over them.
    """

    def __init__(
        self,
        node: Node,
        cls: type[T],
        on_change: Callable[[T], None] | None = None,
        skip: tuple[str, ...] = (),
        defaults: dict[str, Any] | None = None,
    ) -> None:
        self._node = node
        self._cls = cls
        self._on_change = on_change
        self._fields = [f for f in dataclasses.fields(cls) if f.name not in skip]
        values: dict[str, Any] = {}
        overrides = getattr(node, "_parameter_overrides", {})
        defaults = defaults or {}
        for f in self._fields:
            default = defaults.get(f.name, f.default)
            given = overrides.get(f.name)
            if (given is not None and isinstance(f.default, float)
                    and given.type_ == Parameter.Type.INTEGER):
                overrides[f.name] = Parameter(f.name, Parameter.Type.DOUBLE, float(given.value))
            try:
                node.declare_parameter(f.name, _ros_default(default), _descriptor(f))
            except InvalidParameterTypeException:
                raise ValueError(
                    f"parameter '{f.name}' of {node.get_name()}: got {given.value!r} "
                    f"({given.type_.name}), expected {type(_ros_default(f.default)).__name__}"
                ) from None
            except InvalidParameterValueException:
                # outside the descriptor's range: the field's own rule says which bound
                check_field(self._cls, f.name, given.value if given is not None else default)
                raise ValueError(f"parameter '{f.name}' of {node.get_name()}: "
                                 f"{given.value if given is not None else default!r} "
                                 "is out of range") from None
            values[f.name] = node.get_parameter(f.name).value
        self.config: T = self._build(values)
        node.add_on_set_parameters_callback(self._on_set)

    def _build(self, values: dict[str, Any]) -> T:
        kwargs = {name: check_field(self._cls, name, v) for name, v in values.items()}
        return self._cls(**kwargs)

    def _on_set(self, params: list[Parameter]) -> SetParametersResult:
        values = {f.name: getattr(self.config, f.name) for f in self._fields}
        for p in params:
            if p.name in values:
                values[p.name] = p.value
        try:
            new = self._build(values)
        except (ValueError, TypeError) as exc:
            self._node.get_logger().warning(f"rejected parameter change: {exc}")
            return SetParametersResult(successful=False, reason=str(exc))
        if new == self.config:
            return SetParametersResult(successful=True)  # nothing changes
        old, self.config = self.config, new
        if self._on_change is not None:
            try:
                self._on_change(new)
            except Exception as exc:  # noqa: BLE001 - a parameter set never kills the node
                self.config = old
                try:
                    self._on_change(old)
                except Exception:  # noqa: BLE001
                    pass
                self._node.get_logger().error(f"rejected parameter change: applying it "
                                              f"raised {type(exc).__name__}: {exc}")
                return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)


def vehicle_defaults(node: Node, node_key: str) -> dict[str, Any]:
    """Declare ``node``'s ``vehicle_file`` parameter (a shipped car's name or a car file's
    path; empty: the paper's car) and return the parameter defaults the node ``node_key``
    takes from that car (:func:`fourws_common.vehicle_info.node_vehicle_values`), for
    :class:`ParamBinding`'s ``defaults``. The car is read at start: a runtime set of another
    car is refused with the reason, one of the same value (a ``ros2 param load`` of the
    node's own dump) is accepted. ``ValueError`` names a bad file or key."""
    from fourws_common.vehicle_info import load_vehicle_info, node_vehicle_values

    desc = ParameterDescriptor(description="car file: a name in fourws_common/config/"
                               "vehicles or a path; empty: the paper's car (read at start)")
    try:
        name = node.declare_parameter("vehicle_file", "", desc).value
    except InvalidParameterTypeException:
        raise ValueError(f"parameter 'vehicle_file' of {node.get_name()}: expected a string "
                         "(a car's name or a file's path)") from None
    values = node_vehicle_values(node_key, load_vehicle_info(name or None))

    def keep_car(params: list[Parameter]) -> SetParametersResult:
        for p in params:
            if p.name == "vehicle_file" and p.value != name:
                return SetParametersResult(successful=False, reason=(
                    "vehicle_file is read at start: restart the node for another car"))
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(keep_car)
    return values


#: Parameters every rclpy node may be given without declaring them.
BUILTIN_PREFIXES = ("qos_overrides.", "use_sim_time", "start_type_description_service")
#: A params-file value of the first type is accepted for a parameter of the second.
_WIDENING = {(Parameter.Type.INTEGER, Parameter.Type.DOUBLE),
             (Parameter.Type.INTEGER_ARRAY, Parameter.Type.DOUBLE_ARRAY)}


def params_files(argv: list[str]) -> list[str]:
    """The ``--params-file`` paths among the ROS arguments of ``argv``, in order."""
    return [argv[i + 1] for i, a in enumerate(argv[:-1]) if a == "--params-file"]


def check_overrides(node: Node, argv: list[str] | None = None) -> None:
    """Raise ``ValueError`` naming every parameter given to ``node`` that it does not declare
    (a typo such as ``np_baselin`` must not run with the default) or that has another type
    than declared. rcl itself drops a later file's value of another type in silence
    (``np_baseline: 12.5`` over an integer ran with 12), so each ``--params-file`` of
    ``argv`` (default ``sys.argv``) is read here as well."""
    import sys

    from fourws_common.params import load_ros_params_yaml

    argv = sys.argv if argv is None else argv
    given = dict.fromkeys(getattr(node, "_parameter_overrides", {}), "the command line")
    problems: list[str] = []
    for path in params_files(argv):
        try:
            values = load_ros_params_yaml(path, node.get_name())
        except (OSError, ValueError) as exc:
            raise ValueError(f"{node.get_name()}: cannot read params file {path}: {exc}") \
                from None
        for key, value in values.items():
            given[key] = path
            if not node.has_parameter(key) or key.startswith(BUILTIN_PREFIXES):
                continue
            want = node.get_parameter(key).type_
            try:
                got = Parameter(key, value=value).type_
            except TypeError:
                got = None
            if got != want and (got, want) not in _WIDENING:
                problems.append(f"'{key}' in {path} is {value!r} "
                                f"({got.name if got else type(value).__name__}), expected "
                                f"{want.name}")
    unknown = sorted(k for k in given if not node.has_parameter(k)
                     and not k.startswith(BUILTIN_PREFIXES))
    if unknown:
        problems.append(f"unknown parameter(s) {unknown} (not declared by the node; check "
                        f"the spelling; given in {sorted({given[k] for k in unknown})})")
    if problems:
        raise ValueError(f"{node.get_name()}: " + "; ".join(problems))
