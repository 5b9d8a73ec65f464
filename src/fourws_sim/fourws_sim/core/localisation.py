"""Filters the sensors' pose for the controllers: a localisation filter (beyond the paper).

:class:`PoseFilter`, an extended Kalman filter used by every controller alike when a condition
asks for it (``localisation: ekf``; docs/plant.md, "Sensing and localisation"), dead-reckons
with the odometry and corrects towards the fix, knowing the sensors' error models (the σ and τ
of every channel in ``fourws_sim.core.sensing``).

State: the pose p = [x, y, ψ] in the world frame and, for each measured channel whose error
is Gauss-Markov (τ > 0), that error b_c as a state of its own (:data:`FILTERED_CHANNELS`
order). A white error is process noise on what it is integrated into (odometry channels) or
measurement noise (fix channels).

Prediction over one period T, from step k−1 to step k, with the bias-corrected odometry of
both ends of the period (v̂_x = v_x,m − b_vx, v̂_y = v_y,m − b_vy, r̂ = r_m − b_r; a channel
without a bias state uses its measurement), by the trapezoidal rule (second-order exact, so
the estimate does not lag the odometry by half a period)::

    ψ⁺ = ψ + T (r̂_k−1 + r̂_k) / 2
    p⁺ = p + T (w(ψ, v̂_k−1) + w(ψ⁺, v̂_k)) / 2,   w(ψ, v) = R(ψ) [v_x, v_y]  (world frame)
    b⁺ = φ b,  φ = exp(−T/τ),  driving-noise variance σ² (1 − φ²)

A white odometry error enters through both ends of the period (process noise
G_k−1 Σ G_k−1ᵀ + G_k Σ G_kᵀ; the correlation it leaves between consecutive periods is
neglected). Measurement: the fix z = [x_m, y_m, ψ_m] = [x + b_x, y + b_y, ψ + b_ψ] + white;
the heading innovation is wrapped to (−π, π].

The filter's output replaces the measured x, y, ψ and, for the channels with a bias state,
the measured v_x, v_y, r by their bias-corrected values. It starts with the run (prior: the
first fix, the biases at their stationary σ), so its first second is close to the raw fix.
A non-finite measurement or a non-finite estimate restarts it from the next fix; the
restarts are counted (:attr:`PoseFilter.restarts`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from enum import IntEnum
from typing import Any, NamedTuple

import numpy as np

#: ways of localising: the measured state as it is, or :class:`PoseFilter`
LOCALISATION_METHODS = ("none", "ekf")
#: the channels the filter reads, in the order of their bias states
FILTERED_CHANNELS = ("x", "y", "yaw", "vx", "vy", "yaw_rate")
#: per-step process noise on the pose the error models do not explain (the period's
#: integration error, m and rad): far below the sensors' errors, it keeps P positive definite
MODEL_NOISE = (1.0e-5, 1.0e-5, 1.0e-7)
#: white measurement noise floor on a fix (m, m, rad), for a fix without white error
FIX_NOISE_FLOOR = (1.0e-4, 1.0e-4, 1.0e-5)


class _Spec(NamedTuple):
    sigma: float
    tau_s: float


class Pose(IntEnum):
    """Indices of the pose in the filter's state."""

    X = 0
    Y = 1
    YAW = 2


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def _world(psi: float, v_x: float, v_y: float) -> tuple[float, float]:
    c, s = math.cos(psi), math.sin(psi)
    return v_x * c - v_y * s, v_x * s + v_y * c


def predict_pose(p: np.ndarray, odo0: tuple[float, float, float],
                 odo1: tuple[float, float, float], dt_s: float) -> np.ndarray:
    """The pose one period on (module docstring) from the body velocities and yaw rates
    ``odo`` = (v_x, v_y, r) at the start (``odo0``) and the end (``odo1``) of the period."""
    psi1 = p[Pose.YAW] + 0.5 * dt_s * (odo0[2] + odo1[2])
    w0, w1 = _world(p[Pose.YAW], odo0[0], odo0[1]), _world(psi1, odo1[0], odo1[1])
    return np.array([p[Pose.X] + 0.5 * dt_s * (w0[0] + w1[0]),
                     p[Pose.Y] + 0.5 * dt_s * (w0[1] + w1[1]), psi1])


class PoseFilter:
    """The extended Kalman filter of the module docstring for one run.

    ``noise`` is the sensors' error model per channel (objects with ``sigma`` and ``tau_s``,
    as ``sensing.NoiseSpec``; a channel absent or with σ 0 is exact), ``dt_s`` the period
    between measurements.
    """

    def __init__(self, noise: Mapping[str, Any], dt_s: float) -> None:
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise ValueError(f"dt_s: expected > 0, got {dt_s!r}")
        self.dt_s = float(dt_s)
        self.spec = {ch: _Spec(float(getattr(noise.get(ch), "sigma", 0.0)),
                               float(getattr(noise.get(ch), "tau_s", 0.0)))
                     for ch in FILTERED_CHANNELS}
        #: channel -> index of its bias state (Gauss-Markov errors only)
        self.bias_index: dict[str, int] = {}
        for ch in FILTERED_CHANNELS:
            s = self.spec[ch]
            if s.sigma > 0.0 and s.tau_s > 0.0:
                self.bias_index[ch] = len(Pose) + len(self.bias_index)
        self.n = len(Pose) + len(self.bias_index)
        self._phi = np.ones(self.n)
        self._q_bias = np.zeros(self.n)
        self._p0 = np.zeros(self.n)
        for ch, i in self.bias_index.items():
            s = self.spec[ch]
            self._phi[i] = math.exp(-self.dt_s / s.tau_s)
            self._q_bias[i] = s.sigma ** 2 * (1.0 - self._phi[i] ** 2)
            self._p0[i] = s.sigma ** 2
        # white parts: odometry (process) and fix (measurement) noise variances
        self._white = {ch: (self.spec[ch].sigma ** 2 if self.spec[ch].tau_s == 0.0 else 0.0)
                       for ch in FILTERED_CHANNELS}
        self._R = np.diag([self._white[ch] + f * f
                           for ch, f in zip(("x", "y", "yaw"), FIX_NOISE_FLOOR, strict=True)])
        self._H = np.zeros((3, self.n))
        for i, ch in enumerate(("x", "y", "yaw")):
            self._H[i, i] = 1.0
            if ch in self.bias_index:
                self._H[i, self.bias_index[ch]] = 1.0
        self.s: np.ndarray | None = None
        self.P: np.ndarray | None = None
        self._odo: tuple[float, float, float] | None = None
        self.restarts = 0

    # -- the model ---------------------------------------------------------------------
    def _bias(self, s: np.ndarray, ch: str) -> float:
        i = self.bias_index.get(ch)
        return float(s[i]) if i is not None else 0.0

    def _corrected(self, s: np.ndarray, odo: tuple[float, float, float]
                   ) -> tuple[float, float, float]:
        return (odo[0] - self._bias(s, "vx"), odo[1] - self._bias(s, "vy"),
                odo[2] - self._bias(s, "yaw_rate"))

    def transition(self, s: np.ndarray, odo0: tuple[float, float, float],
                   odo1: tuple[float, float, float]) -> np.ndarray:
        """The state one period on from ``s`` with the measured odometry (v_x,m, v_y,m, r_m)
        at the start (``odo0``) and the end (``odo1``) of the period."""
        out = self._phi * s
        out[:len(Pose)] = predict_pose(s[:len(Pose)], self._corrected(s, odo0),
                                       self._corrected(s, odo1), self.dt_s)
        return out

    def jacobians(self, s: np.ndarray, odo0: tuple[float, float, float],
                  odo1: tuple[float, float, float]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(F, G0, G1): ∂transition/∂s and ∂transition/∂(v_x,m, v_y,m, r_m) of the start
        and of the end of the period, at ``s``."""
        T = self.dt_s
        u0, u1 = self._corrected(s, odo0), self._corrected(s, odo1)
        psi0 = float(s[Pose.YAW])
        psi1 = psi0 + 0.5 * T * (u0[2] + u1[2])
        c0, s0, c1, s1 = math.cos(psi0), math.sin(psi0), math.cos(psi1), math.sin(psi1)
        dw0 = (-u0[0] * s0 - u0[1] * c0, u0[0] * c0 - u0[1] * s0)     # ∂w/∂ψ at each end
        dw1 = (-u1[0] * s1 - u1[1] * c1, u1[0] * c1 - u1[1] * s1)
        G0, G1 = np.zeros((self.n, 3)), np.zeros((self.n, 3))
        # d(x, y, ψ)/d(v_x, v_y, r): the start's velocities move p directly; both yaw rates
        # move ψ⁺, and through it the end's world velocity
        G0[Pose.X] = (0.5 * T * c0, -0.5 * T * s0, 0.25 * T * T * dw1[0])
        G0[Pose.Y] = (0.5 * T * s0, 0.5 * T * c0, 0.25 * T * T * dw1[1])
        G0[Pose.YAW] = (0.0, 0.0, 0.5 * T)
        G1[Pose.X] = (0.5 * T * c1, -0.5 * T * s1, 0.25 * T * T * dw1[0])
        G1[Pose.Y] = (0.5 * T * s1, 0.5 * T * c1, 0.25 * T * T * dw1[1])
        G1[Pose.YAW] = (0.0, 0.0, 0.5 * T)
        F = np.diag(self._phi)
        F[Pose.X, Pose.X] = F[Pose.Y, Pose.Y] = F[Pose.YAW, Pose.YAW] = 1.0
        F[Pose.X, Pose.YAW] = 0.5 * T * (dw0[0] + dw1[0])
        F[Pose.Y, Pose.YAW] = 0.5 * T * (dw0[1] + dw1[1])
        for j, ch in enumerate(("vx", "vy", "yaw_rate")):   # v̂ = v_m − b at both ends
            i = self.bias_index.get(ch)
            if i is not None:
                F[:len(Pose), i] = -(G0[:len(Pose), j] + G1[:len(Pose), j])
        return F, G0, G1

    # -- one step ----------------------------------------------------------------------
    def _start(self, z: np.ndarray) -> None:
        self.s = np.zeros(self.n)
        self.s[:len(Pose)] = z
        P = np.diag(self._p0)
        for i, ch in enumerate(("x", "y", "yaw")):
            var = self.spec[ch].sigma ** 2 + FIX_NOISE_FLOOR[i] ** 2
            P[i, i] = var
            j = self.bias_index.get(ch)
            if j is not None:          # x = z − b: the pose and its fix error anticorrelate
                P[i, j] = P[j, i] = -self._p0[j]
        self.P = P

    def update(self, z: tuple[float, float, float], odo: tuple[float, float, float]
               ) -> np.ndarray:
        """One measurement: the fix ``z`` = (x_m, y_m, ψ_m) and the odometry ``odo`` =
        (v_x,m, v_y,m, r_m) of the same step; returns the state estimate after it."""
        z_a = np.asarray(z, dtype=float)
        finite = bool(np.all(np.isfinite(z_a)) and all(math.isfinite(v) for v in odo))
        if not finite:
            if self.s is not None:
                self.restarts += 1
            self.s = self.P = self._odo = None
            return np.full(self.n, math.nan)
        if self.s is None or self.P is None or self._odo is None:
            self._start(z_a)
            self._odo = (float(odo[0]), float(odo[1]), float(odo[2]))
            return self.s.copy()
        with np.errstate(invalid="ignore", over="ignore"):   # a failure restarts, below
            self._step(z_a, (float(odo[0]), float(odo[1]), float(odo[2])))
        self._odo = (float(odo[0]), float(odo[1]), float(odo[2]))
        return self.s.copy()

    def _step(self, z_a: np.ndarray, odo1: tuple[float, float, float]) -> None:
        """Predict over the period (odometry at its start: ``self._odo``; at its end:
        ``odo1``) and update with the fix ``z_a``."""
        assert self.s is not None and self.P is not None and self._odo is not None
        F, G0, G1 = self.jacobians(self.s, self._odo, odo1)
        Qin = np.diag([self._white["vx"], self._white["vy"], self._white["yaw_rate"]])
        Q = G0 @ Qin @ G0.T + G1 @ Qin @ G1.T + np.diag(self._q_bias)
        Q[:len(Pose), :len(Pose)] += np.diag(np.square(MODEL_NOISE))
        self.s = self.transition(self.s, self._odo, odo1)
        self.P = F @ self.P @ F.T + Q
        nu = z_a - self._H @ self.s
        nu[Pose.YAW] = _wrap(float(nu[Pose.YAW]))
        S = self._H @ self.P @ self._H.T + self._R
        try:
            K = np.linalg.solve(S, self._H @ self.P).T
        except np.linalg.LinAlgError:
            K = np.full((self.n, 3), math.nan)       # restarts below
        self.s = self.s + K @ nu
        I_KH = np.eye(self.n) - K @ self._H
        P = I_KH @ self.P @ I_KH.T + K @ self._R @ K.T    # Joseph form
        self.P = 0.5 * (P + P.T)
        if not (np.all(np.isfinite(self.s)) and np.all(np.isfinite(self.P))):
            self.restarts += 1
            self._start(z_a)

    def apply(self, seen: Any) -> bool:
        """Replace ``seen``'s measured pose (and the bias-corrected odometry channels) by the
        filter's estimate, in place; ``False`` (``seen`` untouched) when its measurement is
        not finite."""
        est = self.update((seen.x, seen.y, seen.yaw), (seen.vx, seen.vy, seen.yaw_rate))
        if not np.all(np.isfinite(est)):
            return False
        seen.x, seen.y = float(est[Pose.X]), float(est[Pose.Y])
        seen.yaw = seen.yaw + _wrap(float(est[Pose.YAW]) - seen.yaw)
        for ch in ("vx", "vy", "yaw_rate"):
            i = self.bias_index.get(ch)
            if i is not None:
                setattr(seen, ch, getattr(seen, ch) - float(est[i]))
        return True


def pose_filter(method: str, noise: Mapping[str, Any], dt_s: float
                ) -> PoseFilter | None:
    """The localisation of ``method`` (:data:`LOCALISATION_METHODS`): ``None`` for none."""
    if method not in LOCALISATION_METHODS:
        raise ValueError(f"localisation: '{method}' is not one of {LOCALISATION_METHODS}")
    return PoseFilter(noise, dt_s) if method == "ekf" else None
