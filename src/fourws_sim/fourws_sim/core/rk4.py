"""Integrates the plant by compiled fixed-step RK4 (numba): the simulator's inner loop.

Classical RK4 on the compiled right-hand side :func:`fourws_sim.core.model_jit.derivatives`
(the equations of ``vehicle.py``), in the order of operations of the plain-Python loop it
replaces (kept as ``Simulator(jit=False)``, the tests' oracle; docs/plant.md, "Simulator")::

    k1 = f(y),  k2 = f(y + h/2 k1),  k3 = f(y + h/2 k2),  k4 = f(y + h k3)
    y ← y + h/6 (k1 + 2 (k2 + k3) + k4)

:func:`integrate` runs ``n`` substeps with the command ``u`` and the road ``mu`` held
constant, in place on ``y``; the simulator calls it once per control period on a uniform
road, once per run of substeps with the same command under a steering dead time, and once
per substep where μ changes between substeps (a μ-step road). :func:`outputs` evaluates the
model once for the plant outputs.
"""

from __future__ import annotations

import numba
import numpy as np

from fourws_sim.core.model_jit import ALPHA, FX, FY, FZ, N_ROWS, derivatives

N_AUX = 18
"""Length of the array :func:`outputs` returns: a_x, a_y, then F_x, F_y, F_z and the
kinematic slip angles α, four each (FL FR RL RR)."""
AUX_AX, AUX_AY, AUX_FX, AUX_FY, AUX_FZ, AUX_ALPHA = 0, 1, 2, 6, 10, 14

_jit = numba.njit(cache=True, fastmath=False, error_model="numpy")


@_jit
def integrate(
    y: np.ndarray, u: np.ndarray, mu: np.ndarray, c: np.ndarray, h: float, n: int
) -> None:
    """``n`` RK4 substeps of length ``h`` (s) on the state ``y`` (26,), in place, with the
    command ``u`` (6,) and the road ``mu`` (4,) constant; ``c`` from ``model_constants``."""
    n_state = y.shape[0]
    hh = 0.5 * h
    h6 = h / 6.0
    work = np.empty((5, n_state))  # k1 ... k4 and the stage state
    k1, k2, k3, k4, yt = work[0], work[1], work[2], work[3], work[4]
    wt = np.empty((N_ROWS, 4))
    for _ in range(n):
        derivatives(y, u, mu, c, k1, wt)
        for j in range(n_state):
            yt[j] = y[j] + hh * k1[j]
        derivatives(yt, u, mu, c, k2, wt)
        for j in range(n_state):
            yt[j] = y[j] + hh * k2[j]
        derivatives(yt, u, mu, c, k3, wt)
        for j in range(n_state):
            yt[j] = y[j] + h * k3[j]
        derivatives(yt, u, mu, c, k4, wt)
        for j in range(n_state):
            y[j] = y[j] + h6 * (k1[j] + 2.0 * (k2[j] + k3[j]) + k4[j])


@_jit
def outputs(y: np.ndarray, u: np.ndarray, mu: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The model's a_x, a_y, F_x, F_y, F_z and kinematic α at ``y``: an array of
    :data:`N_AUX`, layout ``AUX_*``."""
    dy = np.empty(y.shape[0])
    wt = np.empty((N_ROWS, 4))
    ax, ay = derivatives(y, u, mu, c, dy, wt)
    aux = np.empty(N_AUX)
    aux[AUX_AX] = ax
    aux[AUX_AY] = ay
    for i in range(4):
        aux[AUX_FX + i] = wt[FX, i]
        aux[AUX_FY + i] = wt[FY, i]
        aux[AUX_FZ + i] = wt[FZ, i]
        aux[AUX_ALPHA + i] = wt[ALPHA, i]
    return aux
