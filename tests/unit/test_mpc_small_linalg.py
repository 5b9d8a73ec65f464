"""The small dense kernels (``small_linalg``) against numpy: the product and the solve agree
to round-off on random and ill-conditioned matrices, a singular matrix is reported, and the
pivoting handles a zero leading entry."""

from __future__ import annotations

import numpy as np
import pytest

from fourws_mpc.core.small_linalg import matmul_into, solve_into


@pytest.mark.parametrize("shape", [(1, 1, 1), (3, 5, 2), (10, 10, 10), (12, 7, 20)])
def test_matmul_into_is_the_matrix_product(shape):
    n, k, m = shape
    rng = np.random.default_rng(n * 100 + k * 10 + m)
    A, B = rng.normal(size=(n, k)), rng.normal(size=(k, m))
    out = np.full((n, m), np.nan)                   # every entry is written
    matmul_into(A, B, out)
    np.testing.assert_allclose(out, A @ B, rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("n, m", [(1, 1), (4, 3), (10, 20), (25, 2)])
def test_solve_into_is_the_linear_solve(n, m):
    rng = np.random.default_rng(n + m)
    M, rhs = rng.normal(size=(n, n)), rng.normal(size=(n, m))
    expected = np.linalg.solve(M, rhs)
    work, x = M.copy(), rhs.copy()
    assert solve_into(work, x)
    np.testing.assert_allclose(x, expected, rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(M @ x, rhs, atol=1e-10)


def test_solve_into_pivots_past_a_zero_leading_entry():
    M = np.array([[0.0, 2.0, 1.0], [1.0, 1.0, 0.0], [3.0, 0.0, 1.0]])
    rhs = np.array([[1.0], [2.0], [3.0]])
    x = rhs.copy()
    assert solve_into(M.copy(), x)
    np.testing.assert_allclose(M @ x, rhs, atol=1e-14)


def test_solve_into_is_accurate_on_an_ill_conditioned_matrix():
    """A graded matrix (condition ~1e10, like I + G H of the DARE's doubling late in its
    run): the residual stays at round-off relative to the data."""
    rng = np.random.default_rng(7)
    U, _ = np.linalg.qr(rng.normal(size=(10, 10)))
    M = U @ np.diag(np.logspace(0, -10, 10)) @ U.T
    rhs = rng.normal(size=(10, 3))
    x = rhs.copy()
    assert solve_into(M.copy(), x)
    assert np.abs(M @ x - rhs).max() <= 1e-12 * np.abs(M).max() * np.abs(x).max()


def test_solve_into_reports_a_singular_matrix():
    M = np.array([[1.0, 2.0], [2.0, 4.0]])
    assert not solve_into(np.zeros((3, 3)), np.ones((3, 1)))
    x = np.ones((2, 1))
    ok = solve_into(M.copy(), x)
    # elimination leaves an exact zero pivot (2·row 0 − row 1 is exactly 0 in floating point)
    assert not ok
