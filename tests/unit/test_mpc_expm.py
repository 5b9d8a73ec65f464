"""The compiled matrix exponential against ``scipy.linalg.expm``, the oracle, on every Padé
degree and on the scaled branch."""

import numpy as np
import pytest
import scipy.linalg

from fourws_mpc.core.expm import expm


@pytest.mark.parametrize("norm", [0.0, 1e-3, 0.1, 0.5, 1.5, 4.0, 30.0, 500.0])
@pytest.mark.parametrize("n", [1, 6, 14])
def test_expm_equals_scipys(norm, n):
    rng = np.random.default_rng(int(norm * 1000) + n)
    A = rng.normal(size=(n, n))
    if norm:
        A *= norm / np.abs(A).sum(axis=0).max()
    else:
        A[:] = 0.0
    want = scipy.linalg.expm(A)
    got = expm(A)
    # e^A's own conditioning grows with ‖A‖ (the squarings): compare relative to its size
    assert np.abs(got - want).max() <= 1e-13 * max(1.0, norm) * np.abs(want).max()


def test_expm_of_a_zoh_block_keeps_its_structure():
    """expm(T [[A, B], [0, 0]]) has [0, I] below: the bottom rows come out exact."""
    rng = np.random.default_rng(3)
    M = np.zeros((14, 14))
    M[:10, :] = rng.normal(size=(10, 14))
    E = expm(0.01 * M)
    np.testing.assert_array_equal(E[10:, 10:], np.eye(4))
    np.testing.assert_array_equal(E[10:, :10], 0.0)
