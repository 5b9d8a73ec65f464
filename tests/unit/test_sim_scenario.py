"""Scenarios: loading, drivability against μ g, ends and aborts, the simulator built from one."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from fourws_common.params import load_ros_params_yaml
from fourws_common.resources import config_dir
from fourws_sim.core.paths import lateral_error
from fourws_sim.core.scenario import (
    AbortLimits,
    list_scenarios,
    load_scenario,
    scenario_from_mapping,
    scenarios_dir,
)
from fourws_sim.core.simulator import Simulator

REQUIRED = {"dlc_60_mu05", "dlc_90_mu06", "circle_mu10", "iso3888_80_mu08", "mu_step", "split_mu"}

_PLANT = load_ros_params_yaml(str(config_dir("fourws_sim") / "plant.yaml"), "plant_node")
ABORT = AbortLimits.of(_PLANT["abort_lateral_error_m"], _PLANT["abort_sideslip_deg"])
TIGHT = AbortLimits.of(3.0, 15.0)  # limits a test sets for itself


def _raw(name: str) -> dict:
    return yaml.safe_load((scenarios_dir() / f"{name}.yaml").read_text(encoding="utf-8"))


def test_every_shipped_scenario_loads_and_is_drivable():
    names = set(list_scenarios())
    assert REQUIRED <= names
    for name in names:
        s = load_scenario(name)
        assert s.name == name
        assert s.peak_lat_accel_demand_mps2 <= s.mu_g_mps2 or s.allow_over_mu
        print(f"{name}: {s.summary()}")


@pytest.mark.parametrize("name, speed, mu, stretch", [("dlc_60_mu05", 60.0, 0.5, 60 / 36),
                                                     ("dlc_90_mu06", 90.0, 0.6, 2.5)])
def test_paper_scenarios_ask_for_less_than_07_mu_g(name, speed, mu, stretch):
    s = load_scenario(name)
    assert s.speed_mps == pytest.approx(speed / 3.6)
    assert s.mu_g_mps2 == pytest.approx(mu * 9.81)
    assert s.demand_ratio < 0.7
    # the stretched path keeps the 10 m/s demand (≈ 2.7 m/s²) and ends at Y = −1.65 m
    assert s.peak_lat_accel_demand_mps2 == pytest.approx(2.8, abs=0.15)
    assert np.max(np.abs(s.path.curvature)) * stretch**2 == pytest.approx(0.0271, rel=0.05)
    assert np.interp(s.end_x_m, s.path.x, s.path.y) == pytest.approx(-1.65, abs=0.03)
    t_run = (s.end_x_m - s.initial.x) / s.speed_mps
    assert 8.0 <= t_run <= 12.0


def test_summary_format():
    s = load_scenario("dlc_60_mu05")
    text = s.summary()
    assert text.startswith("path peak lateral-acceleration demand ")
    assert f"= {s.demand_ratio:.2f} μg (μ = 0.5)" in text


def test_demand_above_mu_g_raises_unless_allowed():
    raw = _raw("dlc_60_mu05")
    raw["path"] = {"type": "tanh_dlc", "stretch": 1.0}  # as printed: ≈ 7.5 m/s² at 60 km/h
    with pytest.raises(ValueError, match="allow_over_mu"):
        scenario_from_mapping(raw)
    raw["allow_over_mu"] = True
    s = scenario_from_mapping(raw)
    assert s.peak_lat_accel_demand_mps2 == pytest.approx(7.5, abs=0.3)
    assert s.demand_ratio > 1.0


@pytest.mark.parametrize(
    "change, match",
    [({"colour": "red"}, "colour"), ({"speed_kmh": -5.0}, "speed_kmh"),
     ({"vehicle": {"mass_kg": -1.0}}, "mass_kg"), ({"initial": {"z_m": 1.0}}, "z_m"),
     ({"allow_over_mu": "yes"}, "allow_over_mu"), ({"road": {"type": "ice"}}, "road.type"),
     ({"abort": {"sideslip_deg": 0.0}}, "abort")],
)
def test_bad_scenarios_raise_naming_the_key(change, match):
    raw = _raw("dlc_60_mu05")
    raw.update(change)
    with pytest.raises(ValueError, match=match):
        scenario_from_mapping(raw)


def test_on_path_start_puts_the_car_on_the_reference_with_its_heading():
    """The tanh path is dy1/2 (1 + tanh z1) ≈ 1.98 mm off Y = 0 at X = 0 (z1 ≈ −3.81): a car at
    the origin would start with that lateral error; on_path starts it on the path."""
    raw = _raw("dlc_60_mu05")
    assert raw["initial"]["on_path"] is True
    s = scenario_from_mapping(raw)
    z1, z2 = 2.4 / 25.0 * (0.0 - 27.19) - 1.2, 2.4 / 21.95 * (0.0 - 56.46) - 1.2
    y_ref = 4.05 / 2 * (1 + math.tanh(z1)) - 5.7 / 2 * (1 + math.tanh(z2))
    assert s.initial.y == pytest.approx(y_ref, rel=1e-6)
    i0 = int(np.argmin(np.abs(s.path.x)))
    assert s.initial.x == 0.0 and s.initial.yaw == float(s.path.yaw[i0]) > 0.0
    out = Simulator.from_scenario(s).outputs()
    assert abs(lateral_error(s.path, out.x, out.y)) < 1e-12
    assert lateral_error(s.path, 0.0, 0.0) == pytest.approx(-s.initial.y, rel=1e-6)


@pytest.mark.parametrize("initial, match", [({"on_path": True, "yaw_deg": 1.0}, "yaw_deg"),
                                            ({"on_path": "yes"}, "on_path")])
def test_on_path_start_rejects_contradictions(initial, match):
    raw = _raw("dlc_60_mu05")
    raw["initial"] = initial
    with pytest.raises(ValueError, match=match):
        scenario_from_mapping(raw)


def test_needs_an_end():
    raw = _raw("dlc_60_mu05")
    del raw["end_x_m"], raw["duration_s"]
    with pytest.raises(ValueError, match="end_x_m"):
        scenario_from_mapping(raw)


def test_load_by_path_and_vehicle_overrides(tmp_path: Path):
    raw = _raw("circle_mu10")
    raw["vehicle"] = {"mass_kg": 800.0}
    raw["name"] = "heavy_circle"
    f = tmp_path / "heavy.yaml"
    f.write_text(yaml.safe_dump(raw, allow_unicode=True), encoding="utf-8")
    s = load_scenario(str(f))
    assert s.name == "heavy_circle" and s.vehicle.mass_kg == 800.0 and s.source == f
    with pytest.raises(ValueError, match="not found"):
        load_scenario("no_such_scenario")


def test_simulator_from_scenario_starts_at_the_initial_state():
    s = load_scenario("dlc_90_mu06")
    sim = Simulator.from_scenario(s)
    out = sim.outputs()
    assert out.t_s == 0.0 and out.x == s.initial.x and out.vx == pytest.approx(25.0)
    np.testing.assert_allclose(out.wheel_speed, 25.0 / s.vehicle.wheel_radius_m)
    np.testing.assert_array_equal(out.wheel_torque, 0.0)
    np.testing.assert_array_equal(out.mu, 0.6)
    assert s.check_end(sim.outputs(), ABORT) == (False, "")


def test_check_end_reasons():
    s = load_scenario("dlc_60_mu05")
    sim = Simulator.from_scenario(s)
    out = sim.outputs()
    out.x, out.y = s.end_x_m + 0.1, -1.65
    done, reason = s.check_end(out, TIGHT)
    assert done and "end_x_m" in reason and not reason.startswith("aborted")
    out.x, out.y = 50.0, float(np.interp(50.0, s.path.x, s.path.y)) + 3.5
    done, reason = s.check_end(out, TIGHT)
    assert done and reason.startswith("aborted: lateral error")
    out.y = float(np.interp(50.0, s.path.x, s.path.y))
    out.sideslip = math.radians(20.0)
    done, reason = s.check_end(out, TIGHT)
    assert done and reason.startswith("aborted: sideslip")
    out.sideslip, out.t_s = 0.0, s.duration_s
    assert s.check_end(out, TIGHT)[0]


def test_open_loop_straight_run_drifts_off_the_lane_change_path_and_is_aborted():
    """The path turns; a car that drives straight ends up > abort limit off it."""
    s = load_scenario("dlc_60_mu05")
    sim = Simulator.from_scenario(s)
    torque = np.full(4, 15.0)
    for _ in range(2000):
        out = sim.step(0.0, 0.0, torque)
        done, reason = s.check_end(out, TIGHT)
        if done:
            break
    assert done and reason.startswith("aborted: lateral error")
    assert abs(lateral_error(s.path, out.x, out.y)) > TIGHT.lateral_error_m


@pytest.mark.parametrize("name", sorted(REQUIRED))
def test_a_simple_pure_pursuit_driver_completes_every_scenario(name):
    """End-to-end: plant + scenario are drivable. Pure pursuit (look-ahead 0.9 v, ≥ 5 m) with
    understeer compensation, proportional speed law; no abort, errors well inside the limit."""
    s = load_scenario(name)
    sim = Simulator.from_scenario(s)
    out = sim.outputs()
    p, veh = s.path, s.vehicle
    k_us = veh.understeer_gradient()
    e_max = 0.0
    for _ in range(5000):
        i = int(np.argmin((p.x - out.x) ** 2 + (p.y - out.y) ** 2))
        ahead = max(5.0, 0.9 * out.vx)
        j = min(int(np.searchsorted(p.s, p.s[i] + ahead)), len(p) - 1)
        alpha = math.atan2(p.y[j] - out.y, p.x[j] - out.x) - out.yaw
        delta = 2.0 * math.sin(alpha) / ahead * (veh.wheelbase_m + k_us * out.vx**2)
        force = veh.mass_kg * 2.0 * (p.speed[i] - out.vx) + 0.37 * out.vx**2 + 88.0
        out = sim.step(delta, 0.0, np.full(4, force * veh.wheel_radius_m / 4))
        e_max = max(e_max, abs(lateral_error(p, out.x, out.y)))
        done, reason = s.check_end(out, ABORT)
        if done:
            break
    assert done and reason.startswith("end of scenario"), reason
    assert e_max < 1.0


def test_abort_limits_have_one_owner_the_plant_parameters():
    """A scenario cannot set abort limits (the plant's parameters are their one source)."""
    raw = _raw("dlc_60_mu05")
    raw["abort"] = {"lateral_error_m": 3.0}
    with pytest.raises(ValueError, match="abort"):
        scenario_from_mapping(raw)
    s = load_scenario("dlc_60_mu05")
    out = Simulator.from_scenario(s).outputs()
    out.y += 2.0                                   # 2 m off the path
    assert s.check_end(out, AbortLimits.of(1.0, 30.0))[1].startswith("aborted: lateral")
    assert s.check_end(out, AbortLimits.of(3.0, 30.0)) == (False, "")
