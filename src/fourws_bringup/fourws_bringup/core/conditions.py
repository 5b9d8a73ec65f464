"""Conditions of a run: what the controllers see and how late their commands act.

A condition (docs/bench.md, "Conditions") is the bench around the controllers, separate from
the scenario (road, path, speed): measurement noise per channel (``fourws_sim.core.sensing``),
a computation delay of N control periods, a steering dead time, where the allocator's and the
MPC's tyre data come from (``oracle``: the plant's true per-wheel F_z, F_y and μ, the paper's
idealised setting; ``estimated``: ``fourws_torque_alloc.core.tyre_estimate`` from the
measured a_x, a_y and a configured nominal μ), MPC parameter overrides (model mismatch: the
controller's mass, inertia or cornering stiffness against the plant's), plant overrides over
the scenario's vehicle (``vehicle_overrides``, e.g. a slower steering actuator), and a seed.
``IDEAL`` is the paper's setting. In a realistic condition the controllers receive the state
of ``fourws_sim.core.sensing.Sensors``: measured channels with their noise and, with
estimated tyre data, zero in every tyre force, load and adhesion field, so no plant truth can
leak into them. :func:`node_parameters` is the one translation of a condition into node
parameters.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fourws_common.params import read_yaml_file
from fourws_common.vehicle_info import vehicle_path
from fourws_sim.core.localisation import LOCALISATION_METHODS
from fourws_sim.core.sensing import CHANNELS, MAX_SEED, TYRE_SOURCES, NoiseSpec, noise_specs
from fourws_sim.core.simulator import MAX_STEER_DEAD_TIME_S as MAX_DEAD_TIME_S


@dataclass(frozen=True)
class Condition:
    """One condition (module docstring); SI units."""

    name: str = "ideal"
    noise: Mapping[str, NoiseSpec] = field(default_factory=dict)
    delay_periods: int = 0
    steer_dead_time_s: float = 0.0
    tyre_forces: str = "oracle"
    mu_nominal: float = 0.8
    mpc_overrides: Mapping[str, Any] = field(default_factory=dict)
    #: allocator parameter overrides (a study of the allocation methods)
    allocator_overrides: Mapping[str, Any] = field(default_factory=dict)
    vehicle_overrides: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0
    #: tell the MPC the delay and dead time (its ``input_delay_periods``,
    #: ``steer_dead_time_s``), as a car's integrator who measured them would: the MPC then
    #: compensates them (``fourws_mpc.core.delay``). Off: the controller does not know them.
    known_delays: bool = False
    #: how the controllers' pose is localised (``fourws_sim.core.localisation``): ``none``,
    #: the measured state as it is (the paper's and the bench's default); ``ekf``, a
    #: localisation filter that knows the sensors' error models (beyond the paper)
    localisation: str = "none"
    #: the car (:mod:`fourws_common.vehicle_info`: a shipped name or a car file's path; empty:
    #: the paper's car). The plant and every controller read it, so it is no mismatch
    vehicle: str = ""

    def __post_init__(self) -> None:
        if self.tyre_forces not in TYRE_SOURCES:
            raise ValueError(f"tyre_forces: '{self.tyre_forces}' is not one of {TYRE_SOURCES}")
        if self.localisation not in LOCALISATION_METHODS:
            raise ValueError(f"localisation: '{self.localisation}' is not one of "
                             f"{LOCALISATION_METHODS}")
        if not (isinstance(self.delay_periods, int) and 0 <= self.delay_periods <= 100):
            raise ValueError(f"delay_periods: expected an integer 0..100, got "
                             f"{self.delay_periods!r}")
        if not 0.01 <= self.mu_nominal <= 3.0:
            raise ValueError(f"mu_nominal: {self.mu_nominal} outside 0.01..3")
        if not 0.0 <= self.steer_dead_time_s <= MAX_DEAD_TIME_S:   # False for NaN too
            raise ValueError(f"steer_dead_time_ms: {self.steer_dead_time_s * 1e3:g} outside "
                             f"0..{MAX_DEAD_TIME_S * 1e3:g}")
        if not (isinstance(self.seed, int) and 0 <= self.seed <= MAX_SEED):
            raise ValueError(f"seed: expected an integer 0..{MAX_SEED} (the noise streams "
                             f"take 32 bits), got {self.seed!r}")
        unknown = sorted(set(self.noise) - set(CHANNELS))
        if unknown:
            raise ValueError(f"noise: unknown channel(s) {unknown}")

    @property
    def ideal(self) -> bool:
        """The paper's setting: truth in, no delay, oracle tyre data, no override."""
        return (not any(s.sigma > 0.0 for s in self.noise.values()) and not self.delay_periods
                and not self.steer_dead_time_s and self.tyre_forces == "oracle"
                and not self.mpc_overrides and not self.vehicle_overrides
                and not self.allocator_overrides
                and self.localisation == "none")


IDEAL = Condition()
#: the nodes a condition sets parameters of (:func:`node_parameters`)
NODES = ("plant_node", "mpc_node", "speed_pid_node", "allocator_node")

_KEYS = {"name", "noise", "delay_periods", "steer_dead_time_ms", "tyre_forces", "mu_nominal",
         "mpc_overrides", "allocator_overrides", "vehicle_overrides", "seed", "known_delays",
         "localisation", "vehicle"}


def condition_from_mapping(d: Mapping[str, Any], seed: int | None = None) -> Condition:
    """From YAML: ``noise: {y: {sigma: 0.02, tau_s: 1.0}, ...}``, ``delay_periods``,
    ``steer_dead_time_ms``, ``tyre_forces``, ``mu_nominal``, ``mpc_overrides``, ``seed``,
    ``known_delays``, ``localisation``, ``vehicle``."""
    if not isinstance(d, Mapping):
        raise ValueError(f"condition: a mapping of {sorted(_KEYS)}, got {d!r}")
    unknown = sorted(set(d) - _KEYS)
    if unknown:
        raise ValueError(f"condition: unknown key(s) {unknown} (known: {sorted(_KEYS)})")
    return Condition(
        name=str(d.get("name", "condition")), noise=noise_specs(d.get("noise")),
        delay_periods=_integer(d.get("delay_periods", 0), "delay_periods"),
        steer_dead_time_s=_number(d.get("steer_dead_time_ms", 0.0), "steer_dead_time_ms") * 1e-3,
        tyre_forces=str(d.get("tyre_forces", "oracle")),
        mu_nominal=_number(d.get("mu_nominal", 0.8), "mu_nominal"),
        mpc_overrides=_mapping(d.get("mpc_overrides"), "mpc_overrides"),
        allocator_overrides=_mapping(d.get("allocator_overrides"), "allocator_overrides"),
        vehicle_overrides=_mapping(d.get("vehicle_overrides"), "vehicle_overrides"),
        seed=_integer(d["seed"] if seed is None and "seed" in d else (seed or 0), "seed"),
        known_delays=_flag(d.get("known_delays", False), "known_delays"),
        localisation=str(d.get("localisation", "none")),
        vehicle=str(d.get("vehicle") or ""))


def _integer(v: Any, name: str) -> int:
    """An integer as YAML gives it (``2``, or ``2.0``); ``ValueError`` for 1.9, true or text."""
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or \
            v != int(v):
        raise ValueError(f"{name}: expected an integer, got {v!r}")
    return int(v)


def _number(v: Any, name: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise ValueError(f"{name}: expected a number, got {v!r}")
    return float(v)


def _mapping(v: Any, name: str) -> dict[str, Any]:
    if v is None:
        return {}
    if not isinstance(v, Mapping):
        raise ValueError(f"{name}: expected a mapping of parameter names to values, got {v!r}")
    return dict(v)


def _flag(v: Any, name: str) -> bool:
    if not isinstance(v, bool):
        raise ValueError(f"{name}: expected true or false, got {v!r}")
    return v


def packaged_conditions() -> list[str]:
    """Names of the conditions shipped in ``fourws_bringup/config/conditions``."""
    return sorted(p.stem for p in _conditions_dir().glob("*.yaml"))


def _conditions_dir() -> Path:
    from fourws_common.resources import config_dir

    return config_dir("fourws_bringup") / "conditions"


def condition_mapping(raw: Any, _bases: tuple[str, ...] = ()) -> dict[str, Any]:
    """A condition's mapping from a spec entry: the mapping itself (``None`` is ideal), the
    name of a shipped condition (``realistic``: ``config/conditions/realistic.yaml``), so a
    spec and ``fourws paper`` share one definition, or a mapping with ``base: NAME``: that
    shipped condition with the mapping's other keys over it
    (``{base: realistic, localisation: ekf}``). A key replaces the base's whole value: a
    ``noise`` given here is the condition's entire noise, not a change of some channels."""
    if raw is None:
        return {}
    if isinstance(raw, str):
        path = _conditions_dir() / f"{raw}.yaml"
        if not path.is_file():
            raise ValueError(f"condition '{raw}': no such shipped condition (shipped: "
                             f"{', '.join(packaged_conditions())})")
        raw = read_yaml_file(path)
    if not isinstance(raw, Mapping):
        raise ValueError(f"condition: a mapping of {sorted(_KEYS)} or a shipped condition's "
                         f"name, got {raw!r}")
    raw = dict(raw)
    base = raw.pop("base", None)
    if base is None:
        return raw
    if not isinstance(base, str):
        raise ValueError(f"condition base: the name of a shipped condition, got {base!r}")
    if base in _bases:
        raise ValueError(f"condition base: '{base}' is its own base "
                         f"({' -> '.join((*_bases, base))})")
    return {**condition_mapping(base, (*_bases, base)), **raw}


def load_condition(arg: str, seed: int | None = None) -> Condition:
    """The condition named by ``arg``: a shipped condition's name (``realistic``),
    ``FILE.yaml`` holding one condition mapping, or ``SPEC.yaml#NAME``, the condition NAME of
    a sweep spec (its top-level ``conditions`` or any group's); ``seed`` overrides the
    condition's own. ``ValueError`` names what is wrong.
    """
    path, _, name = arg.partition("#")
    if not name and not path.endswith((".yaml", ".yml")) and path in packaged_conditions():
        return condition_from_mapping({**condition_mapping(path), "name": path}, seed)
    data = read_yaml_file(path)
    if name:
        groups = [data] + list(data.get("groups") or []) if isinstance(data, Mapping) else []
        found = [g["conditions"][name] for g in groups
                 if isinstance(g, Mapping) and isinstance(g.get("conditions"), Mapping)
                 and name in g["conditions"]]
        if not found:
            raise ValueError(f"{path}: no condition '{name}' among its conditions")
        data = {**condition_mapping(found[0]), "name": name}
    elif not isinstance(data, Mapping):
        raise ValueError(f"{path}: a condition file is a mapping of {sorted(_KEYS)}")
    else:
        data = {"name": Path(path).stem, **data}
    return condition_from_mapping(data, seed)


def node_parameters(condition: Condition) -> dict[str, dict[str, Any]]:
    """The ROS parameters that put ``condition`` on the graph, per node (empty for the ideal
    condition): the one translation, used by ``fourws run`` for the nodes and by the
    in-process loop for its cores, so the graph reproduces the in-process run.

    * ``plant_node``: the sensing and timing (``noise_sigma``/``noise_tau_s`` per channel of
      ``sensing.CHANNELS``, ``noise_seed``, ``delay_periods``, ``steer_dead_time_s``), whether
      the state carries the true tyre data (``tyre_forces``), the localisation filter
      (``localisation``), plant overrides
      (``vehicle_overrides``, a YAML mapping) and ``publish_ground_truth``;
    * ``mpc_node``: the model-mismatch overrides, with ``known_delays`` the delay and dead
      time it compensates, and with estimated tyre data ``mu_default`` = the nominal μ and
      ``mu_from_state`` false (no car measures the adhesion; an adapter's nominal μ in the
      state is not a measurement);
    * ``allocator_node``: the allocator overrides, ``tyre_forces`` and ``mu_nominal``;
    * every node, the car's file as ``vehicle_file`` (absolute) when the condition names one.
    """
    car = {"vehicle_file": str(vehicle_path(condition.vehicle).resolve())} \
        if condition.vehicle else {}
    if condition.ideal:
        return {node: dict(car) for node in NODES}
    plant: dict[str, Any] = {"publish_ground_truth": True, "tyre_forces": condition.tyre_forces}
    if any(spec.sigma > 0.0 for spec in condition.noise.values()):
        zero = NoiseSpec()
        plant["noise_sigma"] = [condition.noise.get(ch, zero).sigma for ch in CHANNELS]
        plant["noise_tau_s"] = [condition.noise.get(ch, zero).tau_s for ch in CHANNELS]
        plant["noise_seed"] = int(condition.seed)
    if condition.localisation != "none":
        plant["localisation"] = condition.localisation
    if condition.delay_periods:
        plant["delay_periods"] = int(condition.delay_periods)
    if condition.steer_dead_time_s:
        plant["steer_dead_time_s"] = float(condition.steer_dead_time_s)
    if condition.vehicle_overrides:
        plant["vehicle_overrides"] = json.dumps(dict(condition.vehicle_overrides),
                                                sort_keys=True)
    mpc = dict(condition.mpc_overrides)
    if condition.known_delays:
        mpc.setdefault("input_delay_periods", int(condition.delay_periods))
        mpc.setdefault("steer_dead_time_s", float(condition.steer_dead_time_s))
    alloc: dict[str, Any] = dict(condition.allocator_overrides)
    if condition.tyre_forces == "estimated":
        mpc.setdefault("mu_default", float(condition.mu_nominal))
        mpc.setdefault("mu_from_state", False)     # whatever a state's μ field holds
        alloc.update({"tyre_forces": "estimated", "mu_nominal": float(condition.mu_nominal)})
    return {"plant_node": {**car, **plant}, "mpc_node": {**car, **mpc},
            "speed_pid_node": dict(car), "allocator_node": {**car, **alloc}}
