"""Computes the matrix exponential, compiled (numba), for the zero-order hold of ``model.zoh``.

Scaling and squaring with a diagonal Padé approximant (Higham, "The scaling and squaring
method for the matrix exponential revisited", SIAM J. Matrix Anal. Appl. 26, 2005, Alg. 2.3):
the degree m ∈ {3, 5, 7, 9, 13} is the lowest with ‖A‖₁ ≤ θ_m; beyond θ_13, A is scaled by
2^−s so that ‖A/2^s‖₁ ≤ θ_13 and the result squared s times. With r_m = p_m(A)/p_m(−A),
p_m(A) = V + U (U the odd, V the even powers), e^A ≈ (V − U)⁻¹ (V + U), accurate to the
unit round-off in exact arithmetic. ``scipy.linalg.expm`` (Al-Mohy & Higham 2009) is the
oracle of the unit test; it is not callable from compiled code, hence this copy (the hold:
docs/mpc.md, "Actuator-aware prediction").
"""

from __future__ import annotations

import numpy as np
from numba import njit

from fourws_mpc.core.small_linalg import solve_into

#: θ_m of Higham (2005), Table 2.3: the largest ‖A‖₁ for which r_m is accurate to 2^−53
_THETA = np.array([1.495585217958292e-2, 2.539398330063230e-1, 9.504178996162932e-1,
                   2.097847961257068e0, 5.371920351148152e0])
_B = (
    np.array([120.0, 60.0, 12.0, 1.0]),
    np.array([30240.0, 15120.0, 3360.0, 420.0, 30.0, 1.0]),
    np.array([17297280.0, 8648640.0, 1995840.0, 277200.0, 25200.0, 1512.0, 56.0, 1.0]),
    np.array([17643225600.0, 8821612800.0, 2075673600.0, 302702400.0, 30270240.0,
              2162160.0, 110880.0, 3960.0, 90.0, 1.0]),
)
_B13 = np.array([64764752532480000.0, 32382376266240000.0, 7771770303897600.0,
                 1187353796428800.0, 129060195264000.0, 10559470521600.0, 670442572800.0,
                 33522128640.0, 1323241920.0, 40840800.0, 960960.0, 16380.0, 182.0, 1.0])


@njit(cache=True)
def _pade_low(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(U, V) of r_m, m = len(b) − 1 ≤ 9: U = A Σ b_{2k+1} A^{2k}, V = Σ b_{2k} A^{2k}."""
    n = A.shape[0]
    A2 = A @ A
    Ap = np.eye(n)                     # A^{2k}
    Uo = b[1] * Ap
    V = b[0] * Ap
    for k in range(1, (b.shape[0] - 1) // 2 + 1):
        Ap = Ap @ A2
        Uo = Uo + b[2 * k + 1] * Ap
        V = V + b[2 * k] * Ap
    return A @ Uo, V


@njit(cache=True)
def _pade13(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(U, V) of r_13 (Higham 2005, eq. 2.8: six products)."""
    n = A.shape[0]
    eye = np.eye(n)
    A2 = A @ A
    A4 = A2 @ A2
    A6 = A2 @ A4
    U = A @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2)
             + b[7] * A6 + b[5] * A4 + b[3] * A2 + b[1] * eye)
    V = (A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2)
         + b[6] * A6 + b[4] * A4 + b[2] * A2 + b[0] * eye)
    return U, V


@njit(cache=True)
def _expm(A: np.ndarray, theta: np.ndarray, b3: np.ndarray,
          b5: np.ndarray, b7: np.ndarray, b9: np.ndarray, b13: np.ndarray) -> np.ndarray:
    norm = np.abs(A).sum(axis=0).max()
    s = 0
    if norm <= theta[3]:
        m = 0
        while norm > theta[m]:
            m += 1
        b = b3
        if m == 1:
            b = b5
        elif m == 2:
            b = b7
        elif m == 3:
            b = b9
        U, V = _pade_low(A, b)
    else:
        if norm > theta[4]:
            s = int(np.ceil(np.log2(norm / theta[4])))
        U, V = _pade13(A / 2.0 ** s, b13)
    E = V + U
    if not solve_into(V - U, E):       # (V − U)⁻¹ (V + U); a NaN A gives NaN through it
        E[:, :] = np.nan                # an exactly singular V − U: no exponential

    for _ in range(s):
        E = E @ E
    return E


@njit(cache=True)
def expm_compiled(A: np.ndarray) -> np.ndarray:
    """e^A of a square float matrix, callable from compiled code."""
    return _expm(A, _THETA, _B[0], _B[1], _B[2], _B[3], _B13)


def expm(A: np.ndarray) -> np.ndarray:
    """e^A of a square float matrix (module docstring)."""
    return _expm(np.ascontiguousarray(A, dtype=float), _THETA, *_B, _B13)
