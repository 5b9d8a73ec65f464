"""Run metrics (metrics.json keys) against hand-computed values and path geometry, and the
in-process closed loop's sequencing on a few steps."""

import math

import numpy as np
import pytest

from fourws_bringup.core.closed_loop import run_closed_loop
from fourws_bringup.core.configs import load_allocator_config
from fourws_bringup.core.metrics import (
    METRIC_KEYS,
    compute_metrics,
    path_errors,
    reference_from_arrays,
    run_metrics,
)


def test_compute_metrics_by_hand():
    ey = np.array([0.1, -0.2, 0.05, 0.0])
    ephi = np.radians([1.0, -3.0, 2.0, 0.0])
    beta = np.radians([0.5, -0.5, 0.0, 1.5])
    m = compute_metrics(ey, ephi, beta, solve_ms=[1.0, 2.0, 3.0, 4.0])
    assert set(m) == set(METRIC_KEYS)
    assert m["max_abs_lateral_error_m"] == pytest.approx(0.2)
    assert m["rmse_lateral_error_m"] == pytest.approx(math.sqrt((0.01 + 0.04 + 0.0025) / 4))
    assert m["mae_lateral_error_m"] == pytest.approx(0.35 / 4)
    assert m["max_abs_heading_error_deg"] == pytest.approx(3.0)
    assert m["rmse_heading_error_deg"] == pytest.approx(math.sqrt((1 + 9 + 4) / 4))
    assert m["max_abs_sideslip_deg"] == pytest.approx(1.5)
    assert m["rmse_sideslip_deg"] == pytest.approx(math.sqrt((0.25 + 0.25 + 2.25) / 4))
    assert m["mpc_solve_ms_p50"] == pytest.approx(2.5)
    assert m["mpc_solve_ms_p99"] == pytest.approx(3.97)
    assert math.isnan(compute_metrics(ey, ephi, beta)["mpc_solve_ms_p99"])


def test_path_errors_on_a_circle_against_geometry():
    R = 30.0
    a = np.linspace(0, 2.0, 2001)
    ref = reference_from_arrays(R * np.sin(a), R * (1 - np.cos(a)), a)
    ang = np.linspace(0.2, 1.8, 50)
    off = 0.3 * np.sin(5 * ang)                       # left of the path = towards the centre
    x = (R - off) * np.sin(ang)
    y = R - (R - off) * np.cos(ang)
    yaw = ang + np.radians(2.0)
    e_y, e_phi = path_errors(ref, x, y, yaw)
    np.testing.assert_allclose(e_y, off, atol=1e-3)
    np.testing.assert_allclose(e_phi, np.radians(2.0), atol=1e-3)


def test_run_metrics_uses_recorded_sideslip_or_velocities():
    x = np.linspace(0, 10, 11)
    ref = reference_from_arrays(np.linspace(0, 20, 201), np.zeros(201), np.zeros(201))
    y = np.full(11, -0.25)
    vx, vy = np.full(11, 10.0), np.full(11, 0.1)
    m = run_metrics(ref, np.arange(11) * 0.01, x, y, np.zeros(11), vx, vy)
    assert m["max_abs_lateral_error_m"] == pytest.approx(0.25)
    assert m["max_abs_sideslip_deg"] == pytest.approx(math.degrees(math.atan2(0.1, 10.0)))
    assert m["steps"] == 11 and m["sim_time_s"] == pytest.approx(0.1)


def test_closed_loop_sequencing_on_a_few_steps():
    log = run_closed_loop("dlc_60_mu05", "mpc_4ws", max_steps=40)
    assert log.steps == 40 and not log.completed and "max_steps" in log.reason
    t = log.state["t_s"]
    np.testing.assert_allclose(np.diff(t), 0.01, atol=1e-12)
    for arr in list(log.state.values()) + list(log.mpc.values()):
        assert len(arr) == 40 and np.all(np.isfinite(arr.astype(float)))
    assert log.state["fz"].shape == (40, 4)
    # mpc_4ws: no DYC, allocation "equal": each wheel gets T_pid / 4
    assert np.all(log.mpc["yaw_moment"] == 0.0)
    assert load_allocator_config("mpc_4ws").method == "equal"
    np.testing.assert_allclose(log.wheel_torque_cmd_nm, np.repeat(
        log.drive_torque_nm[:, None] / 4, 4, axis=1), atol=1e-9)
    # the plant receives the step-k command: its actual steer moves towards it
    assert log.state["steer_front"][0] == 0.0
    m = log.metrics()
    assert m["scenario"] == "dlc_60_mu05" and m["controller"] == "mpc_4ws"
    assert set(METRIC_KEYS) <= set(m)


def test_unknown_controller_is_reported():
    with pytest.raises(ValueError, match="known"):
        run_closed_loop("dlc_60_mu05", "no_such_controller", max_steps=1)
