"""studies/localisation_filter/fusion_floor.py: what a localisation filter could make of the
bench's fixes."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from plant_helpers import plant_output

from fourws_sim.core.sensing import NoiseSpec, Sensors

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location(
    "fusion_floor", ROOT / "studies" / "localisation_filter" / "fusion_floor.py")
ff = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ff)

NOISE = {"y": NoiseSpec(0.02, 1.0), "yaw": NoiseSpec(0.001745, 1.0),
         "yaw_rate": NoiseSpec(0.002)}
DT = 0.01


def test_the_streams_are_the_errors_the_bench_gave_the_controllers():
    sensors = Sensors(NOISE, DT, seed=3)
    seen = [sensors.measure(plant_output()) for _ in range(300)]
    e = ff.streams(NOISE, 3, 300, DT)
    assert e["y"] == pytest.approx([s.y for s in seen], abs=0.0)
    with_vy = {**NOISE, "vy": NoiseSpec(0.035, 1.0)}
    sensors = Sensors(with_vy, DT, seed=3)
    seen_vy = [sensors.measure(plant_output()).vy for _ in range(300)]
    assert ff.streams(with_vy, 3, 300, DT)["vy"] == pytest.approx(seen_vy, abs=0.0)
    assert e["yaw"] == pytest.approx([s.yaw for s in seen], abs=0.0)
    assert e["yaw_rate"] == pytest.approx([s.yaw_rate for s in seen], abs=0.0)
    assert not e["vy"].any() and not e["bias"].any()     # not in this noise, none asked


def test_a_filter_that_trusts_the_fix_returns_it():
    """T_y = T_ψ = one period: each step's estimate is the new fix, error for error."""
    e = ff.streams(NOISE, 5, 500, DT)
    assert ff.complementary(e, 16.7, DT, DT, DT) == pytest.approx(e["y"], abs=1e-15)


def test_perfect_odometry_lets_both_filters_average_the_fix():
    """With no heading error, no gyro noise and no v_y error, the motion between fixes is
    known exactly: after converging, both filters hold the position far inside the fix's
    error (a Gauss-Markov error averages out over many correlation times)."""
    noise = {"y": NoiseSpec(0.02, 1.0), "yaw": NoiseSpec(1e-9, 1.0)}
    e = ff.streams(noise, 1, 6000, DT)
    raw = np.abs(e["y"][3000:]).max()
    kf = np.abs(ff.kalman(e, 16.7, DT, noise)[3000:]).max()
    cf = np.abs(ff.complementary(e, 16.7, DT, 20.0, 20.0)[3000:]).max()
    assert kf < 0.2 * raw and cf < 0.4 * raw


@pytest.mark.parametrize("vy", [None, NoiseSpec(0.035, 1.0), NoiseSpec(0.035)])
def test_the_kalman_filter_has_the_smallest_rms_and_a_gyro_bias_costs_every_filter(vy):
    """The Kalman filter minimises the error's variance: no complementary cell beats its RMS,
    whether v_y is exact, Gauss-Markov (a state of the filter) or white (process noise); a
    gyro bias (not in the bench) makes both worse."""
    noise = NOISE if vy is None else {**NOISE, "vy": vy}
    rows = ff.analyse(noise, [60 / 3.6], seeds=4, steps=1500, dt_s=DT, warmup=1500,
                      grid=((0.5, 1.0), (1.0, 5.0)))
    comp, kf = rows
    assert kf["rms"] < comp["rms"] < comp["raw_rms"]
    cell = ((1.0, 5.0),)                # one cell: the same filter with and without the bias
    clean = ff.analyse(noise, [60 / 3.6], seeds=4, steps=1500, dt_s=DT, warmup=1500, grid=cell)
    biased = ff.analyse(noise, [60 / 3.6], seeds=4, steps=1500, dt_s=DT, warmup=1500,
                        bias=NoiseSpec(0.00175, 100.0), grid=cell)
    assert biased[0]["rms"] > clean[0]["rms"] and biased[1]["rms"] > clean[1]["rms"]


def test_the_command_line_prints_a_row_per_speed_and_estimator(capsys):
    assert ff.main(["--seeds", "2", "--steps", "200", "--warmup-s", "1",
                    "--speeds-kmh", "60"]) == 0
    out = capsys.readouterr().out
    assert out.count("| 60 km/h |") == 2 and "Kalman" in out
