"""The small dense solve (``small_linalg``) against numpy: it agrees to round-off on random
and ill-conditioned matrices, reports a singular matrix, and pivots past a zero leading
entry."""

from __future__ import annotations

import numpy as np
import pytest

from fourws_mpc.core.small_linalg import solve_into


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
