"""A localisation filter between the sensors and the controllers (beyond the paper).

A car's controllers do not take the raw position fix: a localisation filter (Autoware's
``ekf_localizer``, an INS's own fusion) dead-reckons with the odometry and corrects towards
the fix. :class:`PoseFilter` is that filter for the bench: an extended Kalman filter that
knows the sensors' error models (their data sheets: the σ and τ of every channel in
``fourws_sim.core.sensing``), used by every controller alike when a condition asks for it
(``localisation: ekf``).

State: the pose p = [x, y, ψ] in the world frame and, for each measured channel whose error
is Gauss-Markov (τ > 0), that error b_c as a state of its own (:data:`FILTERED_CHANNELS`
order). A white error is process noise on what it is integrated into (odometry channels) or
measurement noise (fix channels).

Prediction over one period T with the previous step's odometry, bias-corrected
(v̂_x = v_x,m − b_vx, v̂_y = v_y,m − b_vy, r̂ = r_m − b_r; a channel without a bias state
uses its measurement), the heading taken at mid-period (second-order exact on an arc)::

    ψ_mid = ψ + T r̂ / 2
    x⁺ = x + T (v̂_x cos ψ_mid − v̂_y sin ψ_mid)
    y⁺ = y + T (v̂_x sin ψ_mid + v̂_y cos ψ_mid)
    ψ⁺ = ψ + T r̂
    b⁺ = φ b,  φ = exp(−T/τ),  driving-noise variance σ² (1 − φ²)

Measurement: the fix z = [x_m, y_m, ψ_m] = [x + b_x, y + b_y, ψ + b_ψ] + white; the heading
innovation is wrapped to (−π, π].

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


def predict_pose(p: np.ndarray, v_x: float, v_y: float, r: float, dt_s: float) -> np.ndarray:
    """The pose one period on (module docstring) with body velocities v_x, v_y and yaw rate r."""
    psi_mid = p[Pose.YAW] + 0.5 * dt_s * r
    c, s = math.cos(psi_mid), math.sin(psi_mid)
    return np.array([p[Pose.X] + dt_s * (v_x * c - v_y * s),
                     p[Pose.Y] + dt_s * (v_x * s + v_y * c),
                     p[Pose.YAW] + dt_s * r])


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

    def transition(self, s: np.ndarray, odo: tuple[float, float, float]) -> np.ndarray:
        """The state one period on from ``s`` with the measured odometry
        ``odo`` = (v_x,m, v_y,m, r_m)."""
        v_x = odo[0] - self._bias(s, "vx")
        v_y = odo[1] - self._bias(s, "vy")
        r = odo[2] - self._bias(s, "yaw_rate")
        out = self._phi * s
        out[:len(Pose)] = predict_pose(s[:len(Pose)], v_x, v_y, r, self.dt_s)
        return out

    def jacobians(self, s: np.ndarray, odo: tuple[float, float, float]
                  ) -> tuple[np.ndarray, np.ndarray]:
        """(F, G): ∂transition/∂s and ∂transition/∂(v_x,m, v_y,m, r_m) at ``s``."""
        T = self.dt_s
        v_x = odo[0] - self._bias(s, "vx")
        v_y = odo[1] - self._bias(s, "vy")
        r = odo[2] - self._bias(s, "yaw_rate")
        psi_mid = s[Pose.YAW] + 0.5 * T * r
        c, sn = math.cos(psi_mid), math.sin(psi_mid)
        dx_dpsi = T * (-v_x * sn - v_y * c)
        dy_dpsi = T * (v_x * c - v_y * sn)
        G = np.zeros((self.n, 3))      # d(x, y, ψ)/d(v_x, v_y, r)
        G[Pose.X] = (T * c, -T * sn, 0.5 * T * dx_dpsi)
        G[Pose.Y] = (T * sn, T * c, 0.5 * T * dy_dpsi)
        G[Pose.YAW] = (0.0, 0.0, T)
        F = np.diag(self._phi)
        F[Pose.X, Pose.X] = F[Pose.Y, Pose.Y] = F[Pose.YAW, Pose.YAW] = 1.0
        F[Pose.X, Pose.YAW], F[Pose.Y, Pose.YAW] = dx_dpsi, dy_dpsi
        for j, ch in enumerate(("vx", "vy", "yaw_rate")):   # v̂ = v_m − b: ∂/∂b = −∂/∂v_m
            i = self.bias_index.get(ch)
            if i is not None:
                F[:len(Pose), i] = -G[:len(Pose), j]
        return F, G

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
        else:
            F, G = self.jacobians(self.s, self._odo)
            Qin = np.diag([self._white["vx"], self._white["vy"], self._white["yaw_rate"]])
            Q = G @ Qin @ G.T + np.diag(self._q_bias)
            Q[:len(Pose), :len(Pose)] += np.diag(np.square(MODEL_NOISE))
            self.s = self.transition(self.s, self._odo)
            self.P = F @ self.P @ F.T + Q
            nu = z_a - self._H @ self.s
            nu[Pose.YAW] = _wrap(float(nu[Pose.YAW]))
            S = self._H @ self.P @ self._H.T + self._R
            K = np.linalg.solve(S, self._H @ self.P).T
            self.s = self.s + K @ nu
            I_KH = np.eye(self.n) - K @ self._H
            self.P = I_KH @ self.P @ I_KH.T + K @ self._R @ K.T    # Joseph form
            if not (np.all(np.isfinite(self.s)) and np.all(np.isfinite(self.P))):
                self.restarts += 1
                self._start(z_a)
        self._odo = (float(odo[0]), float(odo[1]), float(odo[2]))
        return self.s.copy()

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
