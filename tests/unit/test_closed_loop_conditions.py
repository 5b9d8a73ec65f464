"""The in-process loop under a condition: seeds reproduce runs, the ideal condition is the
paper's loop, and in a realistic condition no plant truth reaches the controllers."""

import dataclasses

import numpy as np
import pytest

from fourws_bringup.core.closed_loop import run_closed_loop
from fourws_bringup.core.conditions import IDEAL, Condition, condition_from_mapping
from fourws_sim.core.simulator import Simulator

REALISTIC = condition_from_mapping({
    "name": "all", "noise": {"x": {"sigma": 0.02, "tau_s": 1.0}, "y": {"sigma": 0.02,
                                                                      "tau_s": 1.0},
                             "yaw": {"sigma": 0.0017}, "yaw_rate": {"sigma": 0.002},
                             "ax": {"sigma": 0.05}, "ay": {"sigma": 0.05}},
    "delay_periods": 1, "steer_dead_time_ms": 40, "tyre_forces": "estimated",
    "mu_nominal": 0.5, "seed": 3})
STEPS = 150


def _run(cond, **kw):
    return run_closed_loop("dlc_60_mu05", "improved", STEPS, condition=cond, **kw)


def _same(a, b):
    return all(np.array_equal(a.state[k], b.state[k]) for k in a.state) and \
        all(np.array_equal(a.mpc[k], b.mpc[k]) for k in a.mpc)


def test_the_ideal_condition_is_the_default_loop():
    assert IDEAL.ideal and not REALISTIC.ideal
    assert _same(_run(IDEAL), run_closed_loop("dlc_60_mu05", "improved", STEPS))


def test_a_seed_reproduces_a_realistic_run_bit_for_bit_and_another_differs():
    a, b = _run(REALISTIC), _run(REALISTIC)
    assert _same(a, b)
    c = _run(dataclasses.replace(REALISTIC, seed=4))
    assert not np.array_equal(a.state["y"], c.state["y"])


def test_no_plant_truth_reaches_the_controllers_in_a_realistic_condition(monkeypatch):
    """The plant's tyre forces and adhesion are poisoned: a controller that read them would
    produce NaN or raise; with estimated tyre data the run goes on, finite."""
    real = Simulator.outputs

    def poisoned(self):
        out = real(self)
        out.fz, out.fy, out.mu = (np.full(4, np.nan),) * 3
        return out

    monkeypatch.setattr(Simulator, "outputs", poisoned)
    log = _run(REALISTIC)
    assert log.steps == STEPS
    assert np.all(np.isfinite(log.wheel_torque_cmd_nm))
    assert np.all(np.isfinite(log.mpc["delta_front"]))
    with pytest.raises(ValueError):
        _run(dataclasses.replace(REALISTIC, tyre_forces="oracle"))   # the oracle reads them


def test_metrics_are_computed_on_the_truth_not_the_measurement():
    noisy = Condition(name="noise", noise=REALISTIC.noise, seed=5)
    log = _run(noisy)
    ideal = _run(IDEAL)
    # the truth is smooth: its lateral position never jumps by the noise's size in a step
    assert np.max(np.abs(np.diff(log.state["y"]))) < 0.01
    assert not np.array_equal(log.state["y"], ideal.state["y"])


def test_bad_conditions_are_refused_naming_the_key():
    with pytest.raises(ValueError, match="tyre_forces"):
        Condition(tyre_forces="psychic")
    with pytest.raises(ValueError, match="unknown key"):
        condition_from_mapping({"delay_ms": 10})
    with pytest.raises(ValueError, match="noise.y"):
        condition_from_mapping({"noise": {"y": 0.02}})


@pytest.mark.parametrize(("raw", "key"), [
    ({"steer_dead_time_ms": -20}, "steer_dead_time_ms"),   # made the margins' model overlap
    ({"steer_dead_time_ms": float("nan")}, "steer_dead_time_ms"),
    ({"steer_dead_time_ms": 5000}, "steer_dead_time_ms"),   # beyond the plant's 1 s
    ({"delay_periods": 1.9}, "delay_periods"),              # was truncated to 1
    ({"delay_periods": True}, "delay_periods"),
    ({"delay_periods": None}, "delay_periods"),
    ({"seed": -1}, "seed"),                                 # drew seed 2**32 - 1's noise
    ({"seed": 2**32}, "seed"),                              # drew seed 0's
    ({"mu_nominal": "high"}, "mu_nominal"),
    ({"mpc_overrides": [1]}, "mpc_overrides"),
])
def test_a_bad_value_is_refused_naming_its_key(raw, key):
    with pytest.raises(ValueError, match=key):
        condition_from_mapping(raw)


def test_an_integer_written_as_a_float_is_the_integer():
    c = condition_from_mapping({"delay_periods": 2.0, "seed": 3.0})
    assert (c.delay_periods, c.seed) == (2, 3)
    for key in ("delay_periods", "seed"):           # .inf raised OverflowError, a traceback
        with pytest.raises(ValueError, match=key):
            condition_from_mapping({key: float("inf")})


def test_the_margins_refuse_a_negative_dead_time():
    from fourws_bringup.core.configs import load_mpc_config
    from fourws_bringup.core.margins import closed_loop
    from fourws_sim.core.vehicle_params import load_vehicle_params

    cfg, car = load_mpc_config("mpc_4ws"), load_vehicle_params()
    with pytest.raises(ValueError, match="steer_dead_time_s"):
        closed_loop(cfg, car, 16.7, steer_dead_time_s=-0.02)
    with pytest.raises(ValueError, match="delay_periods"):
        closed_loop(cfg, car, 16.7, delay_periods=-1)


def test_vehicle_overrides_change_the_plant_not_the_controller():
    slow = condition_from_mapping({"name": "slow", "vehicle_overrides": {
        "steer_front_time_constant_s": 0.05, "steer_rear_time_constant_s": 0.05}})
    assert not slow.ideal
    a, b = _run(IDEAL), _run(slow)
    assert not np.array_equal(a.state["steer_front"], b.state["steer_front"])
    with pytest.raises(ValueError, match="wings"):
        _run(condition_from_mapping({"vehicle_overrides": {"wings": 2}}))


def test_the_shipped_realistic_condition_is_named_once_and_shared():
    """``realistic`` (config/conditions/realistic.yaml) is what fourws paper, the bench's
    "all" and the tuning spec's "all" run: one definition, the delays known."""
    from pathlib import Path

    from fourws_bringup.core.conditions import load_condition, packaged_conditions

    root = Path(__file__).resolve().parents[2] / "benchmarks"
    shipped = load_condition("realistic", seed=2)
    assert "realistic" in packaged_conditions()
    for spec in ("robustness.yaml#all", "tuning.yaml#all"):
        assert dataclasses.replace(load_condition(str(root / spec), seed=2),
                                   name="realistic") == shipped, spec
    assert shipped.known_delays and shipped.delay_periods == 1
    assert shipped.steer_dead_time_s == pytest.approx(0.04)
    assert shipped.tyre_forces == "estimated" and shipped.noise["y"].sigma == 0.02
    with pytest.raises(ValueError, match="realistic"):
        from fourws_bringup.core.conditions import condition_mapping

        condition_mapping("surreal")
