"""Sensing: noise statistics from long seeded series, reproducible seeds, exact delays."""

import math

import numpy as np
import pytest

from fourws_sim.core.sensing import (
    DeadTime,
    DelayLine,
    MeasurementNoise,
    NoiseChannel,
    NoiseSpec,
    noise_from_mapping,
)

DT = 0.01


def _series(spec, n, seed=3, name="y"):
    ch = NoiseChannel(spec, DT, seed, name)
    return np.array([ch.sample() for _ in range(n)])


def test_white_noise_has_its_sigma_zero_mean_and_no_correlation():
    e = _series(NoiseSpec(0.02, 0.0), 100_000)
    assert abs(e.mean()) < 4 * 0.02 / math.sqrt(len(e))
    assert e.std() == pytest.approx(0.02, rel=0.02)
    assert abs(np.corrcoef(e[:-1], e[1:])[0, 1]) < 0.02


def test_gauss_markov_has_its_sigma_and_correlation_time():
    tau = 1.0
    e = _series(NoiseSpec(0.02, tau), 400_000)        # 4000 s: 4000 correlation times
    assert e.std() == pytest.approx(0.02, rel=0.05)
    lag = int(tau / DT)
    r = np.corrcoef(e[:-lag], e[lag:])[0, 1]
    assert r == pytest.approx(math.exp(-1.0), abs=0.03)
    r1 = np.corrcoef(e[:-1], e[1:])[0, 1]
    assert r1 == pytest.approx(math.exp(-DT / tau), abs=0.005)


def test_a_seed_reproduces_the_sequence_and_channels_are_independent():
    a = _series(NoiseSpec(0.1, 0.5), 1000, seed=7)
    assert np.array_equal(a, _series(NoiseSpec(0.1, 0.5), 1000, seed=7))
    assert not np.array_equal(a, _series(NoiseSpec(0.1, 0.5), 1000, seed=8))
    one = MeasurementNoise({"y": NoiseSpec(0.1)}, DT, seed=1)
    two = MeasurementNoise({"y": NoiseSpec(0.1), "x": NoiseSpec(0.2)}, DT, seed=1)
    ys1 = [one.errors()["y"] for _ in range(50)]
    ys2 = [two.errors()["y"] for _ in range(50)]
    assert ys1 == ys2          # adding a channel leaves the others' sequences alone


def test_noise_is_added_to_the_state_in_place():
    class S:
        x, y = 1.0, 2.0

    s = S()
    errs = MeasurementNoise({"y": NoiseSpec(0.5)}, DT, seed=2).apply(s)
    assert s.x == 1.0 and s.y == 2.0 + errs["y"] and errs["y"] != 0.0


def test_bad_specs_are_refused_naming_the_key():
    with pytest.raises(ValueError, match="unknown channel"):
        MeasurementNoise({"z": NoiseSpec(0.1)}, DT)
    with pytest.raises(ValueError, match="sigma"):
        NoiseSpec(-1.0)
    with pytest.raises(ValueError, match="noise.y"):
        noise_from_mapping({"y": {"sigma": 0.1, "colour": "pink"}}, DT, 0)


@pytest.mark.parametrize("n", [0, 1, 3])
def test_delay_line_shifts_a_step_by_exactly_n_periods(n):
    d = DelayLine(n, 0.0)
    out = [d.push(1.0 if k >= 5 else 0.0) for k in range(15)]
    assert out.index(1.0) == 5 + n


def test_dead_time_shifts_the_steer_command_by_exactly_its_substeps():
    dt_sub = 40                       # 40 ms at 1 ms substeps
    d = DeadTime(dt_sub, (0.0, 0.0))
    d.command(100, (0.1, 0.0))
    acting = [d.at(i)[0] for i in range(100, 200)]
    assert acting.index(0.1) == dt_sub


@pytest.mark.parametrize("dead_s", [0.03, 0.04])
def test_steering_dead_time_shifts_the_plants_step_response_by_exactly_that_time(dead_s):
    from fourws_sim.core.scenario import load_scenario
    from fourws_sim.core.simulator import Simulator

    s = load_scenario("dlc_60_mu05")
    ref, late = Simulator.from_scenario(s), Simulator.from_scenario(s, steer_dead_time_s=dead_s)
    torque = np.full(4, 20.0)
    a, b = [], []
    for k in range(60):
        cmd = 0.02 if k >= 5 else 0.0
        for sim, out in ((ref, a), (late, b)):
            sim.advance(cmd, 0.0, torque, 0.001)      # 1 ms steps: the substep
            out.append(sim.outputs().steer_front)
    shift = round(dead_s / 0.001)
    assert b[:5 + shift] == [0.0] * (5 + shift)
    np.testing.assert_allclose(b[5 + shift:], a[5:len(b) - shift], rtol=0, atol=1e-12)


def test_dead_time_must_be_a_multiple_of_the_substep():
    from fourws_sim.core.scenario import load_scenario
    from fourws_sim.core.simulator import Simulator

    with pytest.raises(ValueError, match="steer_dead_time_s"):
        Simulator.from_scenario(load_scenario("dlc_60_mu05"), steer_dead_time_s=0.0305)
