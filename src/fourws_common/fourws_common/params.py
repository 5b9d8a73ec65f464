"""Typed, ranged configuration fields for frozen dataclasses (pure Python, no ROS).

Every core's configuration is a frozen dataclass whose fields are declared with :func:`param`
(docs/conventions.md, "Configuration"): the metadata carries the allowed closed range, the
unit and a one-line description. Nodes turn the same metadata into ROS parameter descriptors
with ranges (``fourws_common.ros_params``), so a value is checked by one rule whether it comes
from YAML, the command line or a runtime ``set_parameters`` call.

Files: :func:`read_yaml_file` is the one YAML-file reader (params files, the car file,
scenarios), with errors that name the file and the line; :func:`load_ros_params_yaml` picks
a node's section of a ROS 2 params file.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from os import PathLike
from typing import Any, TypeVar

T = TypeVar("T")


def param(
    default: Any,
    description: str,
    *,
    lo: float | None = None,
    hi: float | None = None,
    unit: str = "",
    choices: tuple[str, ...] | None = None,
) -> Any:
    """A dataclass field with range/choice metadata. Lists are stored as tuples."""
    meta = {"description": description, "lo": lo, "hi": hi, "unit": unit, "choices": choices}
    if isinstance(default, list):
        default = tuple(default)
    return dataclasses.field(default=default, metadata=meta)


def check_field(cls: type, name: str, value: Any) -> Any:
    """Check one value against a field's type, range and choices; return it converted.

    Raises ``ValueError`` naming the field and the rule it breaks.
    """
    fields = {f.name: f for f in dataclasses.fields(cls)}
    if name not in fields:
        raise ValueError(f"{cls.__name__}: unknown parameter '{name}'")
    f = fields[name]
    meta = f.metadata
    default = f.default
    if default is dataclasses.MISSING and f.type in (float, "float"):
        default = 0.0                # a required number (a car file's): checked as one
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ValueError(f"{name}: expected a bool, got {value!r}")
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int | float) or (
                isinstance(value, float) and not math.isfinite(value)) or value != int(value):
            raise ValueError(f"{name}: expected an integer, got {value!r}")
        value = int(value)
    elif isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{name}: expected a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ValueError(f"{name}: must be finite, got {value!r}")
    elif isinstance(default, str):
        if not isinstance(value, str):
            raise ValueError(f"{name}: expected a string, got {value!r}")
        choices = meta.get("choices")
        if choices and value not in choices:
            raise ValueError(f"{name}: '{value}' is not one of {list(choices)}")
        return value
    elif isinstance(default, tuple) and default and all(isinstance(v, str) for v in default):
        # a list of names (a string array parameter)
        if not isinstance(value, list | tuple) or not all(
                isinstance(v, str) and v for v in value):
            raise ValueError(f"{name}: expected a list of non-empty strings, got {value!r}")
        return tuple(value)
    elif isinstance(default, tuple):
        if not isinstance(value, list | tuple):
            raise ValueError(f"{name}: expected a list, got {value!r}")
        value = tuple(float(v) for v in value)
        if not all(math.isfinite(v) for v in value):
            raise ValueError(f"{name}: every element must be finite")
    lo, hi = meta.get("lo"), meta.get("hi")
    unit = meta.get("unit") or ""
    items = value if isinstance(value, tuple) else (value,)
    for v in items:
        if lo is not None and v < lo:
            raise ValueError(f"{name}: {v} is below the minimum {lo} {unit}".rstrip())
        if hi is not None and v > hi:
            raise ValueError(f"{name}: {v} is above the maximum {hi} {unit}".rstrip())
    return value


def from_mapping(cls: type[T], values: Mapping[str, Any], *, strict: bool = True) -> T:
    """Build and validate a config dataclass from a flat mapping of field values.

    Unknown keys raise when ``strict``. Cross-field rules live in the class's
    ``__post_init__`` and raise ``ValueError`` naming the fields.
    """
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = set(values) - names
    if strict and unknown:
        raise ValueError(f"{cls.__name__}: unknown parameter(s) {sorted(unknown)}")
    kwargs = {k: check_field(cls, k, v) for k, v in values.items() if k in names}
    return cls(**kwargs)


def read_yaml_file(path: str | PathLike[str]) -> Any:
    """The YAML content of a file: the one reader of params files, the car file and scenarios.

    Raises ``ValueError`` naming the file (and, for a syntax error, its line and column, on
    one line) when it cannot be read or parsed.
    """
    import yaml

    try:
        with open(path, encoding="utf-8") as fh:
            # libyaml's parser where PyYAML has it (the same safe schema, ~10x faster)
            return yaml.load(fh, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))  # noqa: S506
    except OSError as exc:
        raise ValueError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not UTF-8 text: {exc.reason} at byte {exc.start}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        context = getattr(exc, "context", None)
        cmark = getattr(exc, "context_mark", None)
        if context and cmark is not None:
            context += f" from line {cmark.line + 1}"
        what = f"{problem} ({context})" if context else problem
        what = " ".join(str(what).split())  # one line
        raise ValueError(f"{path}: YAML syntax error{where}: {what}") from None


def load_ros_params_yaml(path: str | PathLike[str], node_name: str) -> dict[str, Any]:
    """Read ``node_name: ros__parameters: {...}`` from a ROS 2 params file.

    Accepts the node name with or without a leading slash, the ``/**`` wildcard and
    ``/**/node_name`` (the node in any namespace, as the packages' files name it); later
    sections override earlier ones as in rcl. Raises ``ValueError`` naming the file
    when it cannot be read (:func:`read_yaml_file`) or is not a mapping.
    """
    data = read_yaml_file(path) or {}
    if not isinstance(data, Mapping):
        raise ValueError(f"{path}: expected a mapping at the top level")
    out: dict[str, Any] = {}
    name = node_name.lstrip("/")
    for key in ("/**", "/**/" + name, name, "/" + name):
        section = data.get(key)
        if isinstance(section, dict):
            out.update(_flatten(section.get("ros__parameters", {}) or {}))
    return out


def _flatten(d: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


def choose(registry: Mapping[str, T], name: str, key: str) -> T:
    """``registry[name]`` for a parameter ``key`` that names one of the registry's entries;
    ``ValueError`` naming the parameter and the known names otherwise."""
    if name not in registry:
        raise ValueError(f"{key}: unknown '{name}' (known: {', '.join(registry)})")
    return registry[name]
