"""The bench's plant side and its translation into node parameters (issue 17): one statement
(``sensing.Sensors``, ``conditions.node_parameters``) for the plant node and the in-process
loop, so a realistic graph run reproduces the in-process one (integration test)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from fourws_bringup.core.conditions import (
    IDEAL,
    condition_from_mapping,
    load_condition,
    node_parameters,
)
from fourws_bringup.supervisor import _param_literal
from fourws_sim.core.scenario import load_scenario
from fourws_sim.core.sensing import CHANNELS, Sensors, sensors_from_params
from fourws_sim.core.simulator import Simulator

SPEC = Path(__file__).resolve().parents[2] / "benchmarks" / "robustness.yaml"


def _outputs():
    return Simulator.from_scenario(load_scenario("dlc_60_mu05")).outputs()


def test_the_ideal_condition_sets_no_parameter_and_passes_the_truth_through():
    assert node_parameters(IDEAL) == {"plant_node": {}, "mpc_node": {}, "speed_pid_node": {},
                                      "allocator_node": {}}
    s = sensors_from_params({}, 0.01)
    out = _outputs()
    assert s.ideal and s.measure(out) is out and s.act("cmd") == "cmd"


def test_a_realistic_condition_becomes_plant_mpc_and_allocator_parameters():
    c = load_condition(f"{SPEC}#all", seed=4)
    p = node_parameters(c)
    plant = p["plant_node"]
    assert plant["publish_ground_truth"] and plant["noise_seed"] == 4
    assert len(plant["noise_sigma"]) == len(plant["noise_tau_s"]) == len(CHANNELS)
    assert plant["noise_sigma"][CHANNELS.index("y")] == 0.02
    assert plant["noise_tau_s"][CHANNELS.index("y")] == 1.0
    assert plant["noise_sigma"][CHANNELS.index("vy")] == 0.035
    assert plant["noise_tau_s"][CHANNELS.index("vx")] == 0.0       # white
    assert plant["delay_periods"] == 1 and plant["steer_dead_time_s"] == pytest.approx(0.04)
    assert plant["tyre_forces"] == "estimated"
    # the state then carries no adhesion: the MPC's bound uses the nominal μ (the
    # friction-aware presets estimate it), whatever a state's μ field holds; the delays are
    # known (measured on the car) and compensated
    assert p["mpc_node"] == {"mu_default": 0.8, "mu_from_state": False,
                             "input_delay_periods": 1,
                             "steer_dead_time_s": pytest.approx(0.04)}
    assert p["allocator_node"] == {"tyre_forces": "estimated", "mu_nominal": 0.8}
    mismatch = node_parameters(load_condition(f"{SPEC}#mismatch_mass_plus20"))
    assert mismatch["mpc_node"] == {"mass_kg": 900.0, "yaw_inertia_kg_m2": 900.0}
    assert "noise_sigma" not in mismatch["plant_node"]


def test_sensed_state_has_noise_once_per_step_and_no_tyre_truth_when_estimated():
    specs = condition_from_mapping({"noise": {"y": {"sigma": 0.02}}}).noise
    out = _outputs()
    a = Sensors(specs, 0.01, seed=1, tyre_forces="estimated")
    b = Sensors(specs, 0.01, seed=1, tyre_forces="oracle")
    sa, sb = a.measure(out), b.measure(out)
    assert sa is not out and sa.y == sb.y != out.y          # same seed, same draw
    assert sa.x == out.x and sa.vx == out.vx                 # only the noisy channel moves
    for name in ("fx", "fy", "fz", "mu"):
        assert not np.any(getattr(sa, name)), name           # no car measures them
        np.testing.assert_array_equal(getattr(sb, name), getattr(out, name))  # the oracle
    assert np.all(out.fz > 0)                                # the plant's own are untouched
    assert a.measure(out).y != sa.y                          # the next step draws again


def test_delay_holds_the_initial_command_for_n_periods():
    s = Sensors(None, 0.01, delay_periods=2, initial_command=0.0)
    assert [s.act(v) for v in (1.0, 2.0, 3.0)] == [0.0, 0.0, 1.0]


def test_vehicle_overrides_travel_as_text_and_name_an_unknown_field():
    sc = load_scenario("dlc_60_mu05")
    c = load_condition(f"{SPEC}#slow_steering_50ms")
    text = node_parameters(c)["plant_node"]["vehicle_overrides"]
    assert isinstance(text, str)
    slow = sc.with_vehicle_overrides(text)
    assert slow.vehicle.steer_front_time_constant_s == 0.05
    assert dataclasses.replace(slow.vehicle, steer_front_time_constant_s=0.02,
                               steer_rear_time_constant_s=0.02) == sc.vehicle
    assert sc.with_vehicle_overrides("") is sc
    with pytest.raises(ValueError, match="wings"):
        sc.with_vehicle_overrides("{wings: 2}")


def test_load_condition_from_a_file_or_a_spec_and_its_errors(tmp_path):
    f = tmp_path / "my_bench.yaml"
    f.write_text("delay_periods: 2\nseed: 7\n")
    c = load_condition(str(f))
    assert (c.name, c.delay_periods, c.seed) == ("my_bench", 2, 7)
    assert load_condition(str(f), seed=1).seed == 1
    with pytest.raises(ValueError, match="no condition 'nope'"):
        load_condition(f"{SPEC}#nope")
    f.write_text("delay_period: 2\n")
    with pytest.raises(ValueError, match="delay_period"):
        load_condition(str(f))


def test_string_parameters_stay_strings_on_the_command_line():
    assert _param_literal("dlc_60_mu05") == "dlc_60_mu05"
    assert _param_literal('{"a": 0.05}') == '"{\\"a\\": 0.05}"'   # a mapping: text
    assert _param_literal("[/a,/b]") == "[/a,/b]"        # YAML on purpose, as on ros2 run
    assert _param_literal([0.0, 0.02]) == "[0.0, 0.02]"


def test_known_delays_are_told_to_the_mpc_only_when_asked():
    base = {"delay_periods": 1, "steer_dead_time_ms": 40}
    assert node_parameters(condition_from_mapping(base))["mpc_node"] == {}
    told = node_parameters(condition_from_mapping({**base, "known_delays": True}))["mpc_node"]
    assert told == {"input_delay_periods": 1, "steer_dead_time_s": pytest.approx(0.04)}
    with pytest.raises(ValueError, match="known_delays"):
        condition_from_mapping({**base, "known_delays": "yes"})


def test_a_condition_extends_a_shipped_one_and_a_base_cycle_is_named(tmp_path, monkeypatch):
    """``base: NAME`` is the shipped condition with the other keys over it (whole values);
    a chain of bases that returns to itself is a clear error, not a recursion."""
    from fourws_bringup.core import conditions

    m = conditions.condition_mapping({"base": "realistic", "delay_periods": 2,
                                      "noise": {"y": {"sigma": 0.01}}})
    real = conditions.condition_mapping("realistic")
    assert m["delay_periods"] == 2 and m["tyre_forces"] == real["tyre_forces"]
    assert m["noise"] == {"y": {"sigma": 0.01}}          # replaced, not merged per channel
    with pytest.raises(ValueError, match="shipped condition"):
        conditions.condition_mapping({"base": 3})
    (tmp_path / "a.yaml").write_text("base: b\ndelay_periods: 1\n")
    (tmp_path / "b.yaml").write_text("base: a\n")
    monkeypatch.setattr(conditions, "_conditions_dir", lambda: tmp_path)
    with pytest.raises(ValueError, match="its own base"):
        conditions.condition_mapping({"base": "a"})
