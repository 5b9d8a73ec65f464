"""Compensates known command delays: predicts over the delay with the commands already sent.

A documented deviation from the paper's assumption (6) that a command acts at once
(``docs/mpc.md``, "Delay compensation"); the scheme of Autoware's MPC lateral controller. With a
computation delay of N periods (a command computed from the state of step k acts from step
k + N, parameter ``input_delay_periods``) and a steering dead time D s (``steer_dead_time_s``,
rounded to n_D = round(D/T) periods), each input channel c has a delay in periods::

    N_δf = N_δr = N + n_D,    N_Mz = N           (the dead time is the steering's alone)

Over [k, k + N_d), N_d = max_c N_c, channel c receives commands already sent: at step k + j the
command u_c(k − N_c + j) if it lies in the past (N_c − j ≥ 1), else — a command not yet
computed, only for a channel with a shorter delay — the last one sent, u_c(k − 1), the same
hold the Δu formulation of eq. (5) assumes. The controller keeps the last max(N_d, 1)
commands (:class:`CommandBuffer`, register i = u(k − 1 − i)), predicts with the discrete
model of eq. (4)::

    ζ(k + j + 1) = A_k ζ(k + j) + B_k u_applied(k + j) + d_k,     j = 0..N_d − 1

(:func:`predict_over_delay`) and optimises from ζ(k + N_d), with the reference horizon starting
at the delayed point (the nearest point advanced by v_x T N_d). Its first move u(k) reaches the
steering at k + N_d, as the QP assumes; u(k − 1) of eq. (5) is register 0 either way.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

from fourws_mpc.core.model import N_INPUT, InputIdx


def channel_delays(input_delay_periods: int, steer_dead_time_s: float, dt_s: float
                   ) -> tuple[int, int, int]:
    """(N_δf, N_δr, N_Mz) in periods (module docstring)."""
    n_dead = int(round(steer_dead_time_s / dt_s))
    d = [0] * N_INPUT
    d[InputIdx.DF] = d[InputIdx.DR] = input_delay_periods + n_dead
    d[InputIdx.MZ] = input_delay_periods
    return tuple(d)  # type: ignore[return-value]


def register_schedule(delays: Sequence[int]) -> np.ndarray:
    """(N_d, 3) int: the buffer register each channel's command comes from at each step
    k + j of the delay (register i = u(k − 1 − i)): max(N_c − j, 1) − 1."""
    n_d = max(delays)
    j = np.arange(n_d)[:, None]
    return np.maximum(np.asarray(delays)[None, :] - j, 1) - 1


def applied_commands(registers: np.ndarray, schedule: np.ndarray) -> np.ndarray:
    """(N_d, 3, …): the command each channel receives at each step of the delay, from the
    registers (register i = u(k − 1 − i)) and :func:`register_schedule`. Trailing axes ride
    along: the stability margins pass each register as the rows of a linear map."""
    return registers[schedule, np.arange(N_INPUT)[None, :]]


def predict_over_delay(Ak: np.ndarray, Bk: np.ndarray, dk: np.ndarray, zeta: np.ndarray,
                       inputs: np.ndarray) -> np.ndarray:
    """ζ after ``len(inputs)`` steps of eq. (4) with the given inputs (N_d, 3); or, with ζ
    (n, m) and inputs (N_d, 3, m), the same recursion on the columns of a linear map (the
    stability margins' form, ``fourws_bringup.core.margins``; dk then zero)."""
    if np.ndim(zeta) == 1:
        f = np.ascontiguousarray
        A, B, d, z, u = (f(Ak, dtype=float), f(Bk, dtype=float), f(dk, dtype=float),
                         f(zeta, dtype=float), f(inputs, dtype=float))
        n, m = z.shape[0], (B.shape[1] if B.ndim == 2 else -1)
        if A.shape != (n, n) or B.shape != (n, m) or d.shape != (n,) or (
                u.ndim != 2 or u.shape[1] != m):
            raise ValueError(f"predict_over_delay: A {A.shape}, B {B.shape}, d {d.shape}, "
                             f"ζ {z.shape}, inputs {u.shape}")
        return _predict_state(A, B, d, z, u)
    z = zeta
    for u in inputs:
        z = Ak @ z + Bk @ u + dk[:, None]
    return z


@njit(cache=True)
def _predict_state(Ak: np.ndarray, Bk: np.ndarray, dk: np.ndarray, zeta: np.ndarray,
                   inputs: np.ndarray) -> np.ndarray:
    """:func:`predict_over_delay` of a state vector, compiled."""
    n, m = Bk.shape
    z = zeta.copy()
    nxt = np.empty(n)
    for k in range(inputs.shape[0]):
        for r in range(n):
            a = 0.0
            for c in range(n):
                a += Ak[r, c] * z[c]
            b = 0.0
            for c in range(m):
                b += Bk[r, c] * inputs[k, c]
            nxt[r] = a + b + dk[r]
        z[:] = nxt
    return z


class CommandBuffer:
    """The last commands sent, newest first: ``registers[i]`` = u(k − 1 − i)."""

    def __init__(self, size: int, u0: np.ndarray) -> None:
        self.registers = np.repeat(np.asarray(u0, float)[None, :], max(size, 1), axis=0)

    def push(self, u: np.ndarray) -> None:
        """Commit u(k): it becomes u(k − 1) of the next step."""
        self.registers[1:] = self.registers[:-1].copy()
        self.registers[0] = u

    def resized(self, size: int) -> CommandBuffer:
        """A buffer of ``size`` registers keeping the newest commands (the oldest repeated)."""
        size = max(size, 1)
        out = CommandBuffer(size, self.registers[-1])
        k = min(size, len(self.registers))
        out.registers[:k] = self.registers[:k]
        return out

    def applied(self, schedule: np.ndarray) -> np.ndarray:
        """(N_d, 3): the command each channel receives at each step of the delay."""
        return applied_commands(self.registers, schedule)
