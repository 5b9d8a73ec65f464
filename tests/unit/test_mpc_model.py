"""3-DOF model of eq. (1): analytic Jacobians against central finite differences; eq. (4)."""

import math

import numpy as np
import pytest
from numdiff_helpers import central_jacobian

from fourws_mpc.core.model import (
    InputIdx,
    ModelParams,
    StateIdx,
    discretise,
    dynamics,
    euler_step,
    jacobians,
)

P = ModelParams()


def _random_points(n, seed=0):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        z = np.array([rng.uniform(-1, 1), rng.uniform(5, 30), rng.uniform(-3, 3),
                      rng.uniform(-0.6, 0.6), rng.uniform(-50, 50), rng.uniform(-50, 200)])
        u = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.15, 0.15),
                      rng.uniform(-1500, 1500)])
        yield z, u


@pytest.mark.parametrize("k", range(20))
def test_jacobians_match_central_differences(k):
    z, u = list(_random_points(20))[k]
    f0, A, B = jacobians(z, u, P)
    np.testing.assert_allclose(f0, dynamics(z, u, P))
    hz = np.array([1e-6, 1e-6, 1e-7, 1e-7, 1e-5, 1e-5])
    hu = np.array([1e-7, 1e-7, 1e-3])
    A_fd = central_jacobian(lambda x: dynamics(x, u, P), z, hz)
    B_fd = central_jacobian(lambda v: dynamics(z, v, P), u, hu)
    np.testing.assert_allclose(A, A_fd, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(B, B_fd, rtol=1e-5, atol=1e-8)


def test_input_jacobian_entries_are_the_corrected_ones():
    z = np.array([0.0, 20.0, 0.0, 0.0, 0.0, 0.0])
    _, _, B = jacobians(z, np.zeros(3), P)
    S, I = StateIdx, InputIdx
    assert B[S.VY, I.DF] == pytest.approx(2 * P.c_cf / P.mass_kg)
    assert B[S.VY, I.DR] == pytest.approx(2 * P.c_cr / P.mass_kg)
    assert B[S.R, I.DF] == pytest.approx(2 * P.a_m * P.c_cf / P.yaw_inertia_kg_m2)
    assert B[S.R, I.DR] == pytest.approx(-2 * P.b_m * P.c_cr / P.yaw_inertia_kg_m2)
    assert B[S.R, I.MZ] == pytest.approx(1 / P.yaw_inertia_kg_m2)


def test_yaw_moment_enters_as_mz_over_iz():
    z = np.array([0.3, 15.0, 0.1, 0.2, 0.0, 0.0])
    d = dynamics(z, np.array([0.02, 0.01, 600.0]), P) - dynamics(z, np.array([0.02, 0.01, 0.0]), P)
    assert d[StateIdx.R] == pytest.approx(600.0 / P.yaw_inertia_kg_m2)
    assert np.count_nonzero(np.abs(d) > 1e-12) == 1


def test_kinematic_rows():
    z = np.array([0.5, 12.0, 0.3, 0.0, 0.0, 0.0])
    f = dynamics(z, np.zeros(3), P)
    assert f[StateIdx.Y] == pytest.approx(12 * math.sin(0.3) + 0.5 * math.cos(0.3))
    assert f[StateIdx.X] == pytest.approx(12 * math.cos(0.3) - 0.5 * math.sin(0.3))
    assert f[StateIdx.PHI] == 0.0


def test_steady_state_matches_linear_single_track_theory():
    # steady cornering of the linear bicycle model: r/δf = vx / (L + K vx²)
    vx = 15.0
    L = P.a_m + P.b_m
    cf, cr = 2 * P.c_cf, 2 * P.c_cr
    K = P.mass_kg / L * (P.b_m / cf - P.a_m / cr)
    delta = 0.01
    _, A, B = jacobians(np.array([0, vx, 0, 0, 0, 0.0]), np.zeros(3), P)
    idx = [StateIdx.VY, StateIdx.R]
    Alat = A[np.ix_(idx, idx)]
    x = np.linalg.solve(Alat, -B[idx, InputIdx.DF] * delta)
    assert x[1] == pytest.approx(vx / (L + K * vx**2) * delta, rel=1e-9)


def test_discretisation_is_forward_euler_and_exact_at_operating_point():
    for z, u in _random_points(5, seed=3):
        dt = 0.01
        Ak, Bk, dk = discretise(z, u, P, dt)
        _, A, B = jacobians(z, u, P)
        np.testing.assert_allclose(Ak, np.eye(6) + dt * A)
        np.testing.assert_allclose(Bk, dt * B)
        np.testing.assert_allclose(Ak @ z + Bk @ u + dk, euler_step(z, u, P, dt), atol=1e-12)


def test_linearisation_error_is_second_order():
    z, u = next(_random_points(1, seed=5))
    Ak, Bk, dk = discretise(z, u, P, 0.01)
    dz = np.array([0.05, 0.2, 0.01, 0.02, 0.1, 0.1])
    du = np.array([0.005, 0.003, 50.0])
    errs = []
    for s in (1.0, 0.5, 0.25):
        lin = Ak @ (z + s * dz) + Bk @ (u + s * du) + dk
        errs.append(np.abs(lin - euler_step(z + s * dz, u + s * du, P, 0.01)).max())
    assert errs[1] / errs[0] == pytest.approx(0.25, rel=0.05)
    assert errs[2] / errs[1] == pytest.approx(0.25, rel=0.05)


def test_speed_floor_keeps_model_finite():
    z = np.array([0.1, 0.0, 0.0, 0.1, 0.0, 0.0])
    f0, A, B = jacobians(z, np.array([0.1, 0.0, 0.0]), P)
    assert np.all(np.isfinite(f0)) and np.all(np.isfinite(A)) and np.all(np.isfinite(B))
