"""Solves the MPC's small dense systems (n ≲ 40) in place, compiled (numba).

At these sizes LAPACK's solve through numba costs more than the arithmetic (argument checks,
copies, an allocation per result); Gaussian elimination into the caller's buffers is faster
(with it and the products into kept buffers, the DARE's doubling of ``terminal_cost`` went
from 51 to 25 µs). Matrix-matrix products stay with BLAS (``np.dot(a, b, out)``), faster
than loops from n = 10 on; a matrix-vector product costs less as a loop than as a BLAS call
(``condense``, ``delay``). A non-finite entry propagates as NaN. ``numpy.linalg.solve`` is the
oracle of the unit test (tests/unit/test_mpc_small_linalg.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def solve_into(M: np.ndarray, rhs: np.ndarray) -> bool:
    """rhs ← M⁻¹ rhs by Gaussian elimination with partial pivoting (M (n, n) is
    overwritten by its factors; rhs (n, m)). False, with both left partly eliminated, if a
    pivot is exactly zero (M singular)."""
    n = M.shape[0]
    m = rhs.shape[1]
    for c in range(n):
        p, big = c, abs(M[c, c])
        for r in range(c + 1, n):
            if abs(M[r, c]) > big:
                p, big = r, abs(M[r, c])
        if big == 0.0:
            return False
        if p != c:
            for j in range(n):
                M[c, j], M[p, j] = M[p, j], M[c, j]
            for j in range(m):
                rhs[c, j], rhs[p, j] = rhs[p, j], rhs[c, j]
        inv = 1.0 / M[c, c]
        for r in range(c + 1, n):
            f = M[r, c] * inv
            if f != 0.0:
                for j in range(c + 1, n):
                    M[r, j] -= f * M[c, j]
                for j in range(m):
                    rhs[r, j] -= f * rhs[c, j]
    for c in range(n - 1, -1, -1):
        inv = 1.0 / M[c, c]
        for j in range(m):
            s = rhs[c, j]
            for l in range(c + 1, n):
                s -= M[c, l] * rhs[l, j]
            rhs[c, j] = s * inv
    return True
