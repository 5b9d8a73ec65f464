#!/usr/bin/env python3
"""Could a localisation filter take the controllers under the localisation floor?

    python studies/localisation_filter/fusion_floor.py [--noise realistic]
        [--speeds-kmh 60 90] [--seeds 60]
        [--steps 4043] [--warmup-s 30] [--no-velocity-noise] [--gyro-bias-sigma 0.0]
        [--gyro-bias-tau-s 100]

The realistic bench gives the controllers a position fix with a slowly wandering error
(Gauss-Markov, σ 2 cm, τ 1 s) and, beside it, a heading fix (0.1°, τ 1 s), a yaw rate (white
0.002 rad/s) and the velocities (v_y: Gauss-Markov 0.035 m/s, τ 1 s). A filter that
dead-reckons with the odometry and corrects towards the fixes trades the fix's error for
the odometry's drift. This tool measures that
trade on the bench's own error streams (``fourws_sim.core.sensing``: the stream of each
(seed, channel), the same draws the runs got), without the controllers.

Straight path along x at speed v, linearised (the paper paths stay within a few degrees of
the x axis): the truth is y = ψ = 0, so whatever an estimator outputs is its error.
Measurements: y_m = n_y, ψ_m = n_ψ, r_m = n_r + b_r, v_y,m = n_vy (the gyro bias b_r is not
in the bench: ``--gyro-bias-sigma`` asks what it would cost; ``--no-velocity-noise`` drops
the condition's velocity errors). Two estimators:

* **complementary** (model-free; what a car's integrator writes first), time constants
  T_y, T_ψ, per step k (period T)::

      ψ̂ ← ψ̂ + T r_m,k;           ψ̂ ← ψ̂ + (T/T_ψ)(ψ_m,k+1 − ψ̂)
      ŷ ← ŷ + T (v ψ̂ + v_y,m,k);   ŷ ← ŷ + (T/T_y)(y_m,k+1 − ŷ)

  over a grid of (T_y, T_ψ); the best cell is reported (chosen on these very streams: a
  bound on what the structure can do, not a tuning).
* **Kalman** (model-aware; a lower bound): the linear Kalman filter with state
  [y, ψ, b_y, b_ψ(, b_r, b_vy)] that knows every error's model and σ exactly — the
  Gauss-Markov errors as states, the white ones as process noise. No real filter knows its
  errors this well. The shipped localisation filter (``fourws_sim.core.localisation``,
  ``localisation: ekf``) is its nonlinear form for the loop; this linear one is written
  independently and is that filter's oracle in the tests.

Both run ``--warmup-s`` on the (stationary) streams before the evaluated ``--steps``: a car's
filter has converged when a manoeuvre starts. Per speed and estimator: the median over seeds
of max |ŷ| over the evaluated steps (the filtered floor) against the median raw floor (max
|n_y| over the same steps, as ``tools/noise_floor.py``), the median ratio of the two, and
the median RMS of ŷ and of n_y. Markdown on stdout, in mm.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Mapping

import numpy as np

from fourws_bringup.core.conditions import load_condition
from fourws_sim.core.sensing import MeasurementNoise, NoiseChannel, NoiseSpec

#: the complementary filter's grid of (T_y, T_ψ) in s
GRID_S = tuple((ty, tp) for ty in (0.1, 0.25, 0.5, 1.0, 2.0) for tp in (0.25, 0.5, 1.0, 2.0, 5.0))
#: the Kalman filter's white measurement noise on the fixes (m, rad): numerical regularisation
#: far below the Gauss-Markov errors it models
KF_R_FLOOR = (1e-4, 1e-5)


def streams(noise: Mapping[str, NoiseSpec], seed: int, steps: int, dt_s: float,
            bias: NoiseSpec | None = None) -> dict[str, np.ndarray]:
    """The errors of one seed's run (the bench's draws on y, yaw, yaw_rate and v_y; the
    optional gyro bias from a stream of its own), one row per step."""
    stream = MeasurementNoise(dict(noise), dt_s, seed)
    rows = [stream.errors() for _ in range(steps)]
    out = {ch: np.array([r.get(ch, 0.0) for r in rows]) for ch in ("y", "yaw", "yaw_rate", "vy")}
    out["bias"] = (_series(NoiseChannel(bias, dt_s, seed, "gyro_bias"), steps)
                   if bias is not None and bias.sigma > 0.0 else np.zeros(steps))
    return out


def _series(ch: NoiseChannel, steps: int) -> np.ndarray:
    return np.array([ch.sample() for _ in range(steps)])


def complementary(e: Mapping[str, np.ndarray], v: float, dt_s: float, t_y: float,
                  t_psi: float) -> np.ndarray:
    """ŷ of the complementary filter (module docstring) on the errors ``e``, per step."""
    y_m, p_m, r_m, vy_m = e["y"], e["yaw"], e["yaw_rate"] + e["bias"], e["vy"]
    a_y, a_p = dt_s / t_y, dt_s / t_psi
    yh, ph = y_m[0], p_m[0]
    out = np.empty(len(y_m))
    out[0] = yh
    for k in range(len(y_m) - 1):
        yh += dt_s * (v * ph + vy_m[k])
        ph += dt_s * r_m[k]
        ph += a_p * (p_m[k + 1] - ph)
        yh += a_y * (y_m[k + 1] - yh)
        out[k + 1] = yh
    return out


def kalman(e: Mapping[str, np.ndarray], v: float, dt_s: float,
           noise: Mapping[str, NoiseSpec], bias: NoiseSpec | None = None) -> np.ndarray:
    """ŷ of the Kalman filter that knows every error model (module docstring), per step.

    State [y, ψ, b_y, b_ψ], plus b_r (gyro bias) and b_vy (a Gauss-Markov v_y error) when
    they exist; a white rate error is process noise on the state it is integrated into."""
    none = NoiseSpec()
    sy, sp = noise["y"], noise["yaw"]
    sr, svy = noise.get("yaw_rate", none), noise.get("vy", none)
    gm = [sy, sp]                    # the Gauss-Markov errors, states 2, 3, ... in this order
    i_r = i_vy = None
    if bias is not None and bias.sigma > 0.0:
        i_r = 2 + len(gm)
        gm.append(bias)
    if svy.sigma > 0.0 and svy.tau_s > 0.0:
        i_vy = 2 + len(gm)
        gm.append(svy)
    n = 2 + len(gm)
    F, Q, P = np.eye(n), np.zeros((n, n)), np.zeros((n, n))
    F[0, 1] = v * dt_s
    for i, spec in enumerate(gm, start=2):
        phi = math.exp(-dt_s / spec.tau_s)
        F[i, i], Q[i, i], P[i, i] = phi, spec.sigma ** 2 * (1 - phi ** 2), spec.sigma ** 2
    P[0, 0], P[1, 1] = sy.sigma ** 2, sp.sigma ** 2
    Q[1, 1] = (dt_s * sr.sigma) ** 2 if sr.tau_s == 0.0 else 0.0
    Q[0, 0] = (dt_s * svy.sigma) ** 2 if i_vy is None else 0.0
    if i_r is not None:
        F[1, i_r] = -dt_s                                   # ψ' = r_m − b_r
    if i_vy is not None:
        F[0, i_vy] = -dt_s                                  # y' = v ψ + v_y,m − b_vy
    H = np.zeros((2, n))
    H[0, 0] = H[0, 2] = H[1, 1] = H[1, 3] = 1.0
    R = np.diag(np.square(KF_R_FLOOR))
    r_m, vy_m, z = e["yaw_rate"] + e["bias"], e["vy"], np.column_stack([e["y"], e["yaw"]])
    x = np.zeros(n)
    out = np.empty(len(r_m))
    for k in range(len(r_m)):
        if k > 0:   # predict with the step's odometry
            x = F @ x
            x[0] += dt_s * vy_m[k - 1]
            x[1] += dt_s * r_m[k - 1]
            P = F @ P @ F.T + Q
        S = H @ P @ H.T + R
        K = np.linalg.solve(S, H @ P).T
        x = x + K @ (z[k] - H @ x)
        P = (np.eye(n) - K @ H) @ P
        out[k] = x[0]
    return out


def analyse(noise: Mapping[str, NoiseSpec], speeds_mps: list[float], seeds: int, steps: int,
            dt_s: float, bias: NoiseSpec | None = None,
            grid: tuple[tuple[float, float], ...] = GRID_S, warmup: int = 0) -> list[dict]:
    """Per speed: the best complementary cell and the Kalman filter over ``steps`` steps
    after ``warmup`` steps of running on the same (stationary) streams."""
    rows = []
    data = [streams(noise, s, warmup + steps, dt_s, bias) for s in range(seeds)]

    def scores(est: np.ndarray) -> tuple[np.ndarray, np.ndarray]:   # per seed: max, RMS
        w = est[:, warmup:]
        return np.abs(w).max(axis=1), np.sqrt(np.mean(w * w, axis=1))

    raw_max, raw_rms = scores(np.array([d["y"] for d in data]))
    for v in speeds_mps:
        cells = {c: scores(np.array([complementary(d, v, dt_s, *c) for d in data]))
                 for c in grid}
        best = min(cells, key=lambda c: float(np.median(cells[c][0])))
        kf = scores(np.array([kalman(d, v, dt_s, noise, bias) for d in data]))
        for name, (mx, rms) in ((f"complementary T_y {best[0]:g} s, T_psi {best[1]:g} s",
                                 cells[best]), ("Kalman (knows every error model)", kf)):
            rows.append({"speed_kmh": v * 3.6, "estimator": name,
                         "median": float(np.median(mx)), "raw": float(np.median(raw_max)),
                         "ratio": float(np.median(mx / raw_max)),
                         "rms": float(np.median(rms)), "raw_rms": float(np.median(raw_rms))})
    return rows


def markdown(rows: list[dict]) -> str:
    lines = ["| speed | estimator | median max \\|ŷ error\\| (mm) | median raw floor (mm) | "
             "median ratio | median RMS (raw) (mm) |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['speed_kmh']:.0f} km/h | {r['estimator']} | {r['median'] * 1e3:.1f}"
                     f" | {r['raw'] * 1e3:.1f} | {r['ratio']:.2f} | {r['rms'] * 1e3:.1f} "
                     f"({r['raw_rms'] * 1e3:.1f}) |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--noise", default="realistic", help="condition (shipped name or file)")
    ap.add_argument("--speeds-kmh", type=float, nargs="+", default=[60.0, 90.0])
    ap.add_argument("--seeds", type=int, default=60, help="seeds 0..N-1 (default 60)")
    ap.add_argument("--steps", type=int, default=4043, help="steps per run (dlc_60: 4043)")
    ap.add_argument("--warmup-s", type=float, default=30.0,
                    help="the filters run this long before the evaluated steps (a car's filter"
                         " is converged when a manoeuvre starts; 0: started with the run)")
    ap.add_argument("--dt", type=float, default=0.01, help="the control period (s)")
    ap.add_argument("--no-velocity-noise", action="store_true",
                    help="drop the condition's v_x, v_y errors (the bench before 2026-12-03)")
    ap.add_argument("--gyro-bias-sigma", type=float, default=0.0, help="gyro bias σ (rad/s)")
    ap.add_argument("--gyro-bias-tau-s", type=float, default=100.0)
    a = ap.parse_args(argv)
    noise = dict(load_condition(a.noise).noise)
    if a.no_velocity_noise:
        noise = {k: v for k, v in noise.items() if k not in ("vx", "vy")}
    if "y" not in noise or "yaw" not in noise:
        print(f"fusion_floor: condition '{a.noise}' needs noise on y and yaw", file=sys.stderr)
        return 2
    bias = NoiseSpec(a.gyro_bias_sigma, a.gyro_bias_tau_s) if a.gyro_bias_sigma > 0 else None
    sys.stdout.write(markdown(analyse(noise, [s / 3.6 for s in a.speeds_kmh], a.seeds,
                                      a.steps, a.dt, bias,
                                      warmup=round(a.warmup_s / a.dt))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
