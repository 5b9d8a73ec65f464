"""Builds a scenario from YAML: a road, a reference path, a speed, a vehicle, an initial state.

A scenario file (``config/scenarios/<name>.yaml``; people's units, converted here;
docs/plant.md, "Scenarios")::

    name: dlc_60_mu05
    description: ...
    speed_kmh: 60                      # reference speed (path.speed), km/h
    road: {type: constant, mu: 0.5}    # or piecewise_x / split, see road.py
    path: {type: tanh_dlc, stretch: auto, ...}   # see paths.py; stretch auto = v/(10 m/s)
    end_x_m: 173                       # end when X ≥ end_x_m ...
    duration_s: 14                     # ... or when t ≥ duration_s (at least one of the two)
    initial: {x_m: 0, y_m: 0, yaw_deg: 0, speed_kmh: 60}   # speed defaults to speed_kmh
    # or {on_path: true, x_m: 0}: start on the path sample nearest to (x_m, y_m), with its
    # heading (a tanh path is 2 mm off Y = 0 at X = 0: this keeps that out of the errors)
    vehicle: {mass_kg: 800}            # optional overrides merged over the car file
    allow_over_mu: false

When a run is aborted (the car left the road or spins) is the plant's parameters, not the
scenario's (``plant.yaml``: ``abort_lateral_error_m``, ``abort_sideslip_deg``;
:class:`AbortLimits`), which :meth:`Scenario.check_end` takes.

Drivability (docs/plant.md, "Drivability"): the path's peak lateral-acceleration demand
max κ v² is computed at the scenario's speed profile and compared with μ g, μ the lowest
adhesion on the road; a demand above μ g raises ``ValueError`` unless ``allow_over_mu: true``.
:meth:`Scenario.summary` gives the one-line statement to print with every run.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from fourws_common.params import read_yaml_file
from fourws_common.path_lookup import PathIndex, nearest_sample
from fourws_common.vehicle_info import vehicle_path
from fourws_sim.core.paths import (
    LEAD_OUT_M,
    ReferencePath,
    lateral_error,
    path_from_mapping,
    peak_lateral_accel_demand,
)
from fourws_sim.core.plant_io import InitialState, PlantOutputs
from fourws_sim.core.road import Road, road_from_mapping
from fourws_sim.core.vehicle_params import VehicleParams, load_vehicle_params

TOP_KEYS = {
    "name", "description", "speed_kmh", "road", "path", "end_x_m", "duration_s", "initial",
    "vehicle", "allow_over_mu",
}
INITIAL_KEYS = {"x_m", "y_m", "yaw_deg", "speed_kmh", "on_path"}


@dataclass(frozen=True)
class AbortLimits:
    """The plant ends a run as aborted beyond these: |lateral error| (m, the car left the
    road) or |sideslip| (rad, above 1 m/s: the car spins). Their one source is the plant's
    parameters ``abort_lateral_error_m`` and ``abort_sideslip_deg`` (:meth:`of`)."""

    lateral_error_m: float
    sideslip_rad: float

    @classmethod
    def of(cls, lateral_error_m: float, sideslip_deg: float) -> AbortLimits:
        """From the plant parameters (m, deg)."""
        return cls(float(lateral_error_m), math.radians(float(sideslip_deg)))


@dataclass(frozen=True, eq=False)
class Scenario:
    """A loaded, validated scenario (SI units)."""

    name: str
    description: str
    speed_mps: float
    road: Road
    path: ReferencePath
    vehicle: VehicleParams
    initial: InitialState
    end_x_m: float | None
    duration_s: float | None
    allow_over_mu: bool
    peak_lat_accel_demand_mps2: float
    mu_g_mps2: float
    source: Path | None = None
    _path_index: PathIndex = field(init=False, repr=False)
    """The abort check's nearest-sample search (its window follows the car; a new object,
    as from ``dataclasses.replace``, starts with a full search)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "_path_index", PathIndex(self.path.x, self.path.y))

    @property
    def demand_ratio(self) -> float:
        """Peak lateral-acceleration demand over μ g."""
        return self.peak_lat_accel_demand_mps2 / self.mu_g_mps2

    def summary(self) -> str:
        """One line: the path's peak lateral-acceleration demand against μ g."""
        mu = self.mu_g_mps2 / self.vehicle.gravity_mps2
        return (
            f"path peak lateral-acceleration demand {self.peak_lat_accel_demand_mps2:.1f} m/s² "
            f"= {self.demand_ratio:.2f} μg (μ = {mu:g})"
        )

    def with_vehicle_overrides(self, overrides: Mapping[str, Any] | str) -> Scenario:
        """This scenario with plant overrides over its vehicle (``VehicleParams`` field names:
        a bench condition's ``vehicle_overrides``), given as a mapping or as its YAML/JSON
        text; empty gives ``self``. ``ValueError`` names an unknown or invalid field."""
        if isinstance(overrides, str):
            text = overrides.strip()
            overrides = yaml.safe_load(text) if text else {}
        if not overrides:
            return self
        if not isinstance(overrides, Mapping):
            raise ValueError(f"vehicle_overrides: expected a mapping, got {overrides!r}")
        known = {f.name for f in dataclasses.fields(self.vehicle)}
        unknown = sorted(set(overrides) - known)
        if unknown:
            raise ValueError(f"vehicle_overrides: unknown vehicle field(s) {unknown}")
        vehicle = dataclasses.replace(self.vehicle, **{k: type(getattr(self.vehicle, k))(v)
                                                      for k, v in overrides.items()})
        return dataclasses.replace(self, vehicle=vehicle)

    def check_end(self, out: PlantOutputs, abort: AbortLimits) -> tuple[bool, str]:
        """(done, reason). Normal ends: end_x_m reached, duration reached, end of the path;
        aborts (reason starts with ``"aborted:"``): |lateral error| or |sideslip| beyond
        ``abort``. (False, "") while the run goes on.

        The lateral error is measured at the path sample nearest to the car, found by a
        windowed search around the previous call's answer (full search on the first call and
        when the window's answer lies on its edge; ``fourws_common.path_lookup``): the index
        of a full search as long as the nearest sample moves by less than 200 samples (10 m at
        the default spacing) between calls, i.e. unless the path comes back near itself."""
        i = self._path_index.nearest(out.x, out.y)
        e = lateral_error(self.path, out.x, out.y, i)
        if abs(e) > abort.lateral_error_m:
            return True, (f"aborted: lateral error {e:+.2f} m beyond "
                          f"±{abort.lateral_error_m:g} m")
        if out.vx > 1.0 and abs(out.sideslip) > abort.sideslip_rad:
            return True, (f"aborted: sideslip {math.degrees(out.sideslip):+.1f}° beyond "
                          f"±{math.degrees(abort.sideslip_rad):g}°")
        if self.end_x_m is not None and out.x >= self.end_x_m:
            return True, f"end of scenario: X = {out.x:.1f} m ≥ end_x_m = {self.end_x_m:g} m"
        if self.duration_s is not None and out.t_s >= self.duration_s - 1e-9:
            return True, (f"end of scenario: t = {out.t_s:.2f} s ≥ "
                          f"duration_s = {self.duration_s:g} s")
        if i >= len(self.path) - 1:
            return True, "end of scenario: end of the reference path reached"
        return False, ""


def scenarios_dir(config_dir: Path | None = None) -> Path:
    """The folder of the scenario YAML files."""
    return _config_dir(config_dir) / "scenarios"


def list_scenarios(config_dir: Path | None = None) -> list[str]:
    """Names of the scenarios shipped in the config folder."""
    return sorted(p.stem for p in scenarios_dir(config_dir).glob("*.yaml"))


def _config_dir(config_dir: Path | None) -> Path:
    if config_dir is not None:
        return Path(config_dir)
    from fourws_common.resources import config_dir as find

    return find("fourws_sim")


def load_scenario(name_or_path: str, config_dir: Path | None = None,
                  vehicle: str | Path | None = None) -> Scenario:
    """Load a scenario by name (``<config_dir>/scenarios/<name>.yaml``, config_dir defaulting
    to the fourws_sim package's) or by file path. Its vehicle overrides are merged over the
    car file ``vehicle`` (a shipped name or a path; default the paper's car). Raises
    ``ValueError`` with the reason (an unreadable file or a YAML syntax error names the file,
    and the line and column of the error)."""
    text = str(name_or_path)
    as_path = Path(text)
    if text.endswith((".yaml", ".yml")) or as_path.is_file():
        path = as_path
    else:
        path = scenarios_dir(config_dir) / f"{text}.yaml"
        if not path.is_file():
            known = ", ".join(list_scenarios(config_dir))
            raise ValueError(f"scenario '{text}' not found in {path.parent} (known: {known})")
    if not path.is_file():
        raise ValueError(f"scenario file {path} does not exist")
    data = read_yaml_file(path)
    if not isinstance(data, Mapping):
        raise ValueError(f"{path}: expected a mapping at the top level")
    return scenario_from_mapping(data, vehicle_yaml=vehicle_path(vehicle), source=path)


def _number(section: str, key: str, value: Any, lo: float | None = None,
            hi: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{section}{key}: expected a finite number, got {value!r}")
    v = float(value)
    if lo is not None and v < lo:
        raise ValueError(f"{section}{key}: {v} is below the minimum {lo}")
    if hi is not None and v > hi:
        raise ValueError(f"{section}{key}: {v} is above the maximum {hi}")
    return v


def _sub(data: Mapping[str, Any], key: str, allowed: set[str]) -> dict[str, Any]:
    d = data.get(key) or {}
    if not isinstance(d, Mapping):
        raise ValueError(f"{key}: expected a mapping, got {d!r}")
    unknown = set(d) - allowed
    if unknown:
        raise ValueError(f"{key}: unknown key(s) {sorted(unknown)}")
    return dict(d)


def scenario_from_mapping(
    data: Mapping[str, Any],
    vehicle_yaml: Path | None = None,
    source: Path | None = None,
) -> Scenario:
    """Build and validate a scenario from its YAML mapping."""
    unknown = set(data) - TOP_KEYS
    if unknown:
        raise ValueError(f"scenario: unknown key(s) {sorted(unknown)}")
    for key in ("name", "speed_kmh", "road", "path"):
        if key not in data:
            raise ValueError(f"scenario: missing key '{key}'")
    name = str(data["name"])
    speed = _number("", "speed_kmh", data["speed_kmh"], 0.0, 250.0) / 3.6
    end_x = data.get("end_x_m")
    duration = data.get("duration_s")
    if end_x is None and duration is None:
        raise ValueError(f"scenario '{name}': give end_x_m and/or duration_s")
    end_x = None if end_x is None else _number("", "end_x_m", end_x)
    duration = None if duration is None else _number("", "duration_s", duration, 0.01, 3600.0)
    allow = data.get("allow_over_mu", False)
    if not isinstance(allow, bool):
        raise ValueError(f"allow_over_mu: expected true or false, got {allow!r}")

    overrides = data.get("vehicle") or {}
    if not isinstance(overrides, Mapping):
        raise ValueError(f"vehicle: expected a mapping of overrides, got {overrides!r}")
    try:
        vehicle = load_vehicle_params(vehicle_yaml, overrides)
    except ValueError as exc:
        raise ValueError(f"scenario '{name}': vehicle: {exc}") from None

    road = road_from_mapping(data["road"])
    path = path_from_mapping(
        data["path"], speed, None if end_x is None else end_x + LEAD_OUT_M
    )

    ini = _sub(data, "initial", INITIAL_KEYS)
    on_path = ini.get("on_path", False)
    if not isinstance(on_path, bool):
        raise ValueError(f"initial.on_path: expected true or false, got {on_path!r}")
    x0 = _number("initial.", "x_m", ini.get("x_m", 0.0))
    y0 = _number("initial.", "y_m", ini.get("y_m", 0.0))
    yaw0 = math.radians(_number("initial.", "yaw_deg", ini.get("yaw_deg", 0.0)))
    if on_path:
        if "yaw_deg" in ini:
            raise ValueError("initial: yaw_deg and on_path: true exclude each other "
                             "(on the path, the heading is the path's)")
        i = nearest_sample(path.x, path.y, x0, y0)
        x0, y0, yaw0 = float(path.x[i]), float(path.y[i]), float(path.yaw[i])
    initial = InitialState(
        x=x0, y=y0, yaw=yaw0,
        speed=_number("initial.", "speed_kmh", ini.get("speed_kmh", speed * 3.6), 0.0,
                      250.0) / 3.6,
    )

    demand = peak_lateral_accel_demand(path)
    mu_g = road.mu_min() * vehicle.gravity_mps2
    scenario = Scenario(
        name=name,
        description=str(data.get("description", "")),
        speed_mps=speed,
        road=road,
        path=path,
        vehicle=vehicle,
        initial=initial,
        end_x_m=end_x,
        duration_s=duration,
        allow_over_mu=allow,
        peak_lat_accel_demand_mps2=demand,
        mu_g_mps2=mu_g,
        source=source,
    )
    if demand > mu_g and not allow:
        raise ValueError(
            f"scenario '{name}': {scenario.summary()} exceeds μg = {mu_g:.1f} m/s²; stretch or "
            f"slow the path, or set allow_over_mu: true if that is intended"
        )
    return scenario
