"""fourws_sim.core.localisation: the localisation filter between the sensors and the
controllers (beyond the paper): an oracle against an independent linear Kalman filter, its
Jacobians, exactness without noise, what it buys on the bench's own error streams, its
covariance against its errors, and bad input."""

from __future__ import annotations

import dataclasses
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from fourws_bringup.core.conditions import (
    condition_from_mapping,
    condition_mapping,
    load_condition,
    node_parameters,
)
from fourws_sim.core.localisation import Pose, PoseFilter, predict_pose
from fourws_sim.core.sensing import MeasurementNoise, NoiseSpec, Sensors, sensors_from_params

ROOT = Path(__file__).resolve().parents[2]
DT = 0.01


def _fusion_floor():
    spec = importlib.util.spec_from_file_location("fusion_floor",
                                                  ROOT / "tools" / "fusion_floor.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _realistic_noise() -> dict[str, NoiseSpec]:
    return dict(load_condition("realistic").noise)


def _straight(noise, seed: int, steps: int, v: float):
    """The filter on a straight along x at speed v (truth y = ψ = 0, v_y = r = 0) fed the
    bench's error streams of ``seed``: per step the filter's state and the raw errors."""
    f = PoseFilter(noise, DT)
    errs = MeasurementNoise(noise, DT, seed)
    est, raw = [], []
    for k in range(steps):
        e = errs.errors()
        est.append(f.update((v * k * DT + e.get("x", 0.0), e.get("y", 0.0), e.get("yaw", 0.0)),
                            (v + e.get("vx", 0.0), e.get("vy", 0.0), e.get("yaw_rate", 0.0))))
        raw.append(e)
    return f, np.array(est), raw


def test_on_a_straight_the_filter_is_the_linear_kalman_filter_of_fusion_floor():
    """tools/fusion_floor.py's Kalman filter is an independent, linearised formulation (state
    [y, ψ, b_y, b_ψ, b_vy], the straight-path model y' = v ψ + v_y): on the same error
    streams the EKF's lateral estimate agrees with it to well under a millimetre once the
    two priors are forgotten (fusion_floor's starts from zero, this one from the first fix;
    20 s: the mode that tells the fix's error from the position decays slowly)."""
    ff = _fusion_floor()
    noise = _realistic_noise()
    v = 60.0 / 3.6
    for seed in (0, 1):
        _, est, _ = _straight(noise, seed, 4000, v)
        kf = ff.kalman(ff.streams(noise, seed, 4000, DT), v, DT, noise)
        assert np.max(np.abs(est[2000:, Pose.Y] - kf[2000:])) < 2e-4
        assert np.max(np.abs(kf[2000:])) > 0.02   # both see a real error, not zero


def test_the_jacobians_are_the_transitions_derivatives():
    noise = {ch: NoiseSpec(0.03, 2.0) for ch in ("x", "y", "yaw", "vx", "vy", "yaw_rate")}
    f = PoseFilter(noise, DT)
    assert f.n == 3 + 6
    rng = np.random.default_rng(4)
    for _ in range(5):
        s = rng.normal(size=f.n) * 0.3
        s[Pose.YAW] = rng.uniform(-math.pi, math.pi)
        odo = (float(rng.uniform(5, 30)), float(rng.normal()), float(rng.normal() * 0.5))
        F, G = f.jacobians(s, odo)
        h = 1e-6
        F_fd = np.column_stack([(f.transition(s + h * e, odo) - f.transition(s - h * e, odo))
                                / (2 * h) for e in np.eye(f.n)])
        G_fd = np.column_stack([
            (f.transition(s, tuple(np.add(odo, h * e))) - f.transition(s, tuple(np.subtract(
                odo, h * e)))) / (2 * h) for e in np.eye(3)])
        np.testing.assert_allclose(F, F_fd, atol=1e-8)
        np.testing.assert_allclose(G, G_fd, atol=1e-8)


def test_without_noise_the_filter_returns_the_truth_on_an_arc():
    """Exact measurements on a circle (v 20 m/s, r 0.3 rad/s, with side-slip): the
    mid-period heading makes the prediction second-order exact (v T (r T)² / 24 per period,
    under 0.1 µm, which the filter's small fix gain lets add up to some 20 µm), so the
    estimate is the truth although the filter believes the realistic errors."""
    v_x, v_y, r = 20.0, -0.4, 0.3
    speed = math.hypot(v_x, v_y)
    beta = math.atan2(v_y, v_x)
    f = PoseFilter(_realistic_noise(), DT)
    worst = 0.0
    for k in range(1500):
        t = k * DT
        psi = 0.2 + r * t
        # the centre of the circle the CG runs on, radius speed / r
        x = 3.0 + speed / r * (math.sin(psi + beta) - math.sin(0.2 + beta))
        y = -1.0 - speed / r * (math.cos(psi + beta) - math.cos(0.2 + beta))
        s = f.update((x, y, math.atan2(math.sin(psi), math.cos(psi))), (v_x, v_y, r))
        worst = max(worst, abs(s[Pose.X] - x), abs(s[Pose.Y] - y))
        assert abs(math.remainder(s[Pose.YAW] - psi, 2 * math.pi)) < 1e-7
    assert worst < 1e-4


def test_on_the_bench_streams_the_filter_beats_the_raw_fix_where_the_odometry_can():
    """The gyro (0.002 rad/s white) holds the heading far better than the 0.1° fix, and
    the v_y error becomes a state; the position gains less, because dead reckoning drifts
    with the v_y error (tools/fusion_floor.py). Measured after two correlation times."""
    noise = _realistic_noise()
    for seed in (0, 1, 2):
        f, est, raw = _straight(noise, seed, 3000, 60.0 / 3.6)
        w = slice(200, None)
        y_raw = np.array([e["y"] for e in raw])[w]
        psi_raw = np.array([e["yaw"] for e in raw])[w]
        rms = lambda a: float(np.sqrt(np.mean(np.square(a))))  # noqa: E731
        assert rms(est[w, Pose.YAW]) < 0.5 * rms(psi_raw)
        assert rms(est[w, Pose.Y]) < rms(y_raw)
        vy_raw = np.array([e["vy"] for e in raw])[w]
        vy_left = vy_raw - est[w, f.bias_index["vy"]]      # what the corrected v_y keeps
        assert rms(vy_left) < rms(vy_raw)


def test_the_filters_covariance_is_its_error():
    """A filter that knows its errors' models is consistent: its steady-state σ of y is the
    RMS of its y error over long runs (within the sampling spread of ~200 correlation times
    per seed)."""
    noise = _realistic_noise()
    errs, sig = [], []
    for seed in (3, 4, 5):
        f, est, _ = _straight(noise, seed, 8000, 90.0 / 3.6)
        errs.append(est[500:, Pose.Y])
        sig.append(math.sqrt(f.P[Pose.Y, Pose.Y]))
    ratio = float(np.sqrt(np.mean(np.square(np.concatenate(errs))))) / float(np.mean(sig))
    assert 0.8 < ratio < 1.25, ratio


@dataclasses.dataclass
class _Seen:
    x: float = 1.0
    y: float = 2.0
    yaw: float = 0.1
    vx: float = 10.0
    vy: float = 0.0
    yaw_rate: float = 0.0
    ax: float = 0.0
    ay: float = 0.0
    sideslip: float = 0.0
    fx: np.ndarray = dataclasses.field(default_factory=lambda: np.ones(4))
    fy: np.ndarray = dataclasses.field(default_factory=lambda: np.ones(4))
    fz: np.ndarray = dataclasses.field(default_factory=lambda: np.ones(4))
    mu: np.ndarray = dataclasses.field(default_factory=lambda: np.ones(4))


def test_a_non_finite_measurement_is_refused_and_the_filter_starts_again():
    f = PoseFilter(_realistic_noise(), DT)
    assert f.apply(_Seen()) and f.restarts == 0
    bad = _Seen(y=math.nan)
    assert not f.apply(bad) and math.isnan(bad.y) and bad.x == 1.0   # untouched, refused
    assert f.restarts == 1
    good = _Seen(x=5.0, y=-3.0, yaw=-3.1)
    assert f.apply(good)
    assert (good.x, good.y, good.yaw) == (5.0, -3.0, -3.1)     # restarted from this fix
    with pytest.raises(ValueError, match="dt_s"):
        PoseFilter({}, 0.0)


def test_the_heading_estimate_stays_continuous_across_the_wrap():
    """A heading fix that wraps from +π to −π does not make the estimate jump by 2π."""
    f = PoseFilter(_realistic_noise(), DT)
    r = 0.5
    for k in range(200):
        psi = math.pi - 0.5 + r * k * DT
        seen = _Seen(x=0.0, y=0.0, yaw=math.atan2(math.sin(psi), math.cos(psi)), vx=0.0,
                     yaw_rate=r)
        assert f.apply(seen)
        assert abs(math.remainder(seen.yaw - psi, 2 * math.pi)) < 1e-6
        assert abs(seen.yaw - math.atan2(math.sin(psi), math.cos(psi))) < 1e-6


def test_the_localisation_is_a_condition_a_plant_parameter_and_part_of_the_sensors():
    cond = condition_from_mapping(condition_mapping({"base": "realistic",
                                                     "localisation": "ekf"}), seed=2)
    raw = load_condition("realistic", 2)
    assert cond.localisation == "ekf" and not cond.ideal
    assert dict(cond.noise) == dict(raw.noise) and cond.delay_periods == raw.delay_periods
    plant = node_parameters(cond)["plant_node"]
    assert plant["localisation"] == "ekf"
    assert "localisation" not in node_parameters(raw)["plant_node"]
    assert not condition_from_mapping({"localisation": "ekf"}).ideal
    with pytest.raises(ValueError, match="localisation"):
        condition_from_mapping({"localisation": "kalman"})
    with pytest.raises(ValueError, match="no such shipped condition"):
        condition_mapping({"base": "nowhere"})
    # the same errors reach both sensors; the filtered pose is not the raw fix
    plain = sensors_from_params(plant | {"localisation": "none"}, DT)
    filt = sensors_from_params(plant, DT)
    assert isinstance(filt, Sensors) and filt.localiser is not None
    assert plain.localiser is None
    truth = _Seen(vx=0.0)     # standing still: the odometry agrees with the fix
    for _ in range(50):
        a, b = plain.measure(truth), filt.measure(truth)
    assert a.y != b.y and abs(b.y - truth.y) < 0.1
    with pytest.raises(ValueError, match="localisation"):
        Sensors({}, DT, localisation="kalman")


def test_predict_pose_moves_along_the_heading():
    p = predict_pose(np.array([0.0, 0.0, math.pi / 2]), 10.0, 0.0, 0.0, 0.1)
    np.testing.assert_allclose(p, [0.0, 1.0, math.pi / 2], atol=1e-12)
