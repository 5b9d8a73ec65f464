"""Stability margins of the lateral loop, linearised on a straight path at one speed.

**Plant** (docs/bench.md, "Margins"): the plant's linear single-track model with what the
MPC's eq. (1)-(4) leave out, continuous states

    s = [v_y, r, e2, e1, F_yf, F_yr, δ_f, δ_r, M_z, Ṁ_z]

with the plant's per-axle cornering stiffness at static load C_f, C_r (the car file)::

    v̇_y = (F_yf + F_yr)/m − v_x r          ṙ = (a F_yf − b F_yr + M_z)/I_z
    ė2 = r                                  ė1 = v_y + v_x e2
    Ḟ_yf = (C_f α_f − F_yf) v_x/σ_f,  α_f = δ_f − (v_y + a r)/v_x    (tyre relaxation)
    Ḟ_yr = (C_r α_r − F_yr) v_x/σ_r,  α_r = δ_r − (v_y − b r)/v_x
    δ̇_f = (δ_f,cmd − δ_f)/τ_f,  δ̇_r = (δ_r,cmd − δ_r)/τ_r           (steering actuators)
    M_z follows M_z,cmd through the motors' eq. (32)

(σ the relaxation lengths at static load; without relaxation F_y = C α), sampled with a
zero-order hold at the control period T; a computation delay of N periods and a steering dead
time of D periods (rounded to whole periods) are shift registers on the commands. Distance
along the path and speed are not in the loop.

**Controller**: its unconstrained gain at the operating point; for the MPC the first move of
the unconstrained minimiser of eq. (16)-(19) (``MpcController.unconstrained_gain``; disabled
inputs removed) acting on ξ = [ζ; u(k−1)], ζ the path-frame state of its prediction model; for
``lqr_ff`` δ_f = −K x. Its memory, the last max(N_d, 1) commands it sent, is a state of the
loop; with known delays the gain acts on ζ_d = A_k^{N_d} ζ + Σ_j A_k^{N_d−1−j} B_k
u_applied(k + j), as the controller predicts. Its known delays (``input_delay_periods``,
``steer_dead_time_s`` of its config) and the plant's (``delay_periods``, ``steer_dead_time_s``
here) are separate, so a compensation that assumes the wrong delay can be analysed too.

Results: ``spectral_radius`` ρ (largest |eigenvalue| of the closed loop per period: > 1 grows,
by ρ^(1/T) per second), ``frequency_hz`` of that pole, and the margins of the open loop
L(e^{jωT}) from the commanded front steer back to the controller's front steer output, in
negative feedback, the controller's memory closed: ``gain_margin_db`` (the upper margin only;
crossings below 0 dB are not reported), ``phase_margin_deg`` and ``delay_margin_ms``
(:func:`_loop_margins`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from fourws_mpc.core.config import MpcConfig
from fourws_mpc.core.controller import MpcController
from fourws_mpc.core.delay import (
    applied_commands,
    channel_delays,
    predict_over_delay,
    register_schedule,
)
from fourws_mpc.core.lqr import ErrIdx, LqrLateral
from fourws_mpc.core.lqr_controller import lqr_weights
from fourws_mpc.core.model import N_INPUT, N_STATE, StateIdx, zoh
from fourws_mpc.core.relaxation_model import N_STATE_RELAX, RelaxIdx, observer_state_space
from fourws_sim.core.actuators import motor_state_space
from fourws_sim.core.simulator import MAX_STEER_DEAD_TIME_S
from fourws_sim.core.vehicle_params import VehicleParams

#: plant state indices
VY, R, E2, E1, FYF, FYR, DF, DR, MZ, MZD = range(10)
N_PLANT = 10


@dataclass(frozen=True)
class Margins:
    """One linearised loop's figures (module docstring)."""

    spectral_radius: float
    frequency_hz: float
    growth_per_s: float
    gain_margin_db: float | None
    phase_margin_deg: float | None
    speed_mps: float
    delay_margin_ms: float | None = None

    def as_dict(self) -> dict[str, Any]:
        return {"spectral_radius": self.spectral_radius, "frequency_hz": self.frequency_hz,
                "growth_per_s": self.growth_per_s, "gain_margin_db": self.gain_margin_db,
                "phase_margin_deg": self.phase_margin_deg,
                "delay_margin_ms": self.delay_margin_ms, "speed_mps": self.speed_mps}

    def margins_text(self) -> str:
        """"GM x dB / PM y° / DM z ms" ("∞" without a phase crossover above 0 dB, "n/a"
        without a gain crossover or for an unstable loop): the one way reports print them."""
        gm = "∞" if self.gain_margin_db is None else f"{self.gain_margin_db:.1f} dB"
        pm = "n/a" if self.phase_margin_deg is None else f"{self.phase_margin_deg:.1f}°"
        dm = "n/a" if self.delay_margin_ms is None else f"{self.delay_margin_ms:.1f} ms"
        return f"GM {gm} / PM {pm} / DM {dm}"


def plant_matrices(v: VehicleParams, vx: float, relaxation: bool = True
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Continuous (A (10,10), B (10,3)) of the plant above; inputs δ_f,cmd, δ_r,cmd, M_z,cmd."""
    m, iz = v.mass_kg, v.yaw_inertia_kg_m2
    a, b = v.cg_to_front_axle_m, v.cg_to_rear_axle_m
    cf, cr = (2.0 * c for c in v.static_cornering_stiffness())
    fz = v.static_wheel_loads_n
    sig_f, sig_r = (float(s) for s in v.relaxation_length_m(np.array([fz[0], fz[2]])))
    A = np.zeros((N_PLANT, N_PLANT))
    B = np.zeros((N_PLANT, 3))
    A[VY, FYF] = A[VY, FYR] = 1.0 / m
    A[VY, R] = -vx
    A[R, FYF], A[R, FYR], A[R, MZ] = a / iz, -b / iz, 1.0 / iz
    A[E2, R] = 1.0
    A[E1, VY], A[E1, E2] = 1.0, vx
    for f, c, arm, d, sig in ((FYF, cf, a, DF, sig_f), (FYR, cr, -b, DR, sig_r)):
        # α = δ − (v_y + arm r)/v_x;  F = C α (instant) or Ḟ = (C α − F) v_x/σ
        row = np.zeros(N_PLANT)
        row[d], row[VY], row[R] = c, -c / vx, -c * arm / vx
        if relaxation and sig > 0.0:
            A[f] = row * vx / sig
            A[f, f] -= vx / sig
        else:
            A[f] = row          # an algebraic force: made a fast lag of 1e-4 s below
            A[f] /= 1e-4
            A[f, f] = -1.0 / 1e-4
    A[DF, DF], B[DF, 0] = -1.0 / v.steer_front_time_constant_s, 1.0 / v.steer_front_time_constant_s
    A[DR, DR], B[DR, 1] = -1.0 / v.steer_rear_time_constant_s, 1.0 / v.steer_rear_time_constant_s
    Am, Bm, _, _ = motor_state_space(v.motor_time_constant_s)
    A[MZ:MZD + 1, MZ:MZD + 1] = Am
    B[MZ:MZD + 1, 2] = np.asarray(Bm).reshape(-1)
    return A, B


def _zeta(n_model: int, n_ext: int) -> np.ndarray:
    """Map (n_model, n_ext) from the plant state to the MPC's path-frame ζ (vx deviation 0,
    X 0; the actual steering angles for a model with actuator states)."""
    S = np.zeros((n_model, n_ext))
    S[StateIdx.VY, VY] = 1.0
    S[StateIdx.PHI, E2] = 1.0
    S[StateIdx.R, R] = 1.0
    S[StateIdx.Y, E1] = 1.0
    if n_model > N_STATE:
        S[N_STATE, DF] = S[N_STATE + 1, DR] = 1.0      # ActIdx.DF_ACT, ActIdx.DR_ACT
    return S


def _observer(cfg: MpcConfig, vx: float, n: int, i_obs: int, Zs: np.ndarray) -> np.ndarray:
    """The slip observer in the loop, in its own linear form
    (``relaxation_model.observer_state_space``): its memory per axle as a loop state, α̂'
    written into the α' rows of ``Zs``, α the kinematic slip of the plant's v_y, r and
    road-wheel angles. Returns the observer's rows of the loop matrix (n, n)."""
    p = cfg.model_params()
    vxs = max(vx, p.min_speed_mps)
    A = np.zeros((n, n))
    for j, (row, d, arm, sig) in enumerate(((RelaxIdx.ALPHA_F, DF, p.a_m,
                                             p.relaxation_length_front_m),
                                            (RelaxIdx.ALPHA_R, DR, -p.b_m,
                                             p.relaxation_length_rear_m))):
        kin = np.zeros(n)
        kin[d], kin[VY], kin[R] = 1.0, -1.0 / vxs, -arm / vxs
        a_m, b_m, c_m, d_m = observer_state_space(cfg.dt_s, vxs, sig)
        Zs[row] = d_m * kin
        Zs[row, i_obs + j] = c_m
        A[i_obs + j, i_obs + j] = a_m
        A[i_obs + j] += b_m * kin
    return A


def _controller(cfg: MpcConfig) -> MpcController:
    """The MPC whose gain the loop closes (no QP instances built ahead: only its cost)."""
    return MpcController(dataclasses.replace(cfg, qp_prebuild=False))


def model_matrices(cfg: MpcConfig, vx: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A_k, B_k, d_k) of the controller's prediction model at v_x on a straight path, u = 0
    (``MpcController.linearisation``)."""
    return _controller(cfg).linearisation(vx)


def mpc_gain(cfg: MpcConfig, vx: float) -> np.ndarray:
    """K (3, n+3): the MPC's unconstrained first move Δu(k) = −K [ζ; u(k−1)] at (ζ0, u = 0) on
    a straight path, fuzzy weights at e = 0, baseline horizons; n the prediction model's
    state dimension (``MpcController.unconstrained_gain``, on the QP's own condensing)."""
    return _controller(cfg).unconstrained_gain(vx)


def closed_loop(cfg: MpcConfig, v: VehicleParams, vx: float, *, delay_periods: int = 0,
                steer_dead_time_s: float = 0.0, relaxation: bool = True
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A_cl, A_open, B_f, K_f): the closed-loop matrix per period, and the loop broken at
    the front steer command (x+ = A_open x + B_f w, the controller's front steer = K_f x)."""
    if isinstance(delay_periods, bool) or not isinstance(delay_periods, int) or not (
            0 <= delay_periods <= 100):
        raise ValueError(f"delay_periods: an integer 0..100, got {delay_periods!r}")
    if not 0.0 <= steer_dead_time_s <= MAX_STEER_DEAD_TIME_S:     # False for NaN too
        raise ValueError(f"steer_dead_time_s: {steer_dead_time_s} outside "
                         f"0..{MAX_STEER_DEAD_TIME_S:g} s")
    dt = cfg.dt_s
    Ap, Bp = zoh(*plant_matrices(v, vx, relaxation), dt)
    n_dead = int(round(steer_dead_time_s / dt))
    # the controller's known delays and its buffer of commands sent (register i = u(k−1−i))
    known = channel_delays(cfg.input_delay_periods, cfg.steer_dead_time_s, dt)
    n_known = max(known)
    n_mem = N_INPUT * max(n_known, 1)
    # extended state: plant, command delay registers (3 per period), steer dead-time
    # registers (2 per period), controller memory u(k-1), u(k-2), ... (3 each)
    n_del, n_dead_s = 3 * delay_periods, 2 * n_dead
    mpc = _controller(cfg) if cfg.law != "lqr_ff" else None
    Ak, Bk, _ = (mpc.linearisation(vx) if mpc is not None else model_matrices(cfg, vx))
    n_model = Ak.shape[0]
    # the slip observer's memory (2 states) for the relaxation-aware model
    n_obs = 2 if n_model == N_STATE_RELAX else 0
    n = N_PLANT + n_del + n_dead_s + n_mem + n_obs
    i_del, i_dead, i_mem = N_PLANT, N_PLANT + n_del, N_PLANT + n_del + n_dead_s
    i_obs = i_mem + n_mem
    # ζ of the controller's prediction model (with the observer's α̂'), predicted over its
    # known delay with the commands it sent (as delay.predict_over_delay); both laws read it
    Zs = _zeta(n_model, n)
    obs_A = _observer(cfg, vx, n, i_obs, Zs) if n_obs else None
    if n_known:
        registers = np.zeros((n_known, N_INPUT, n))   # register i: u(k−1−i) in the memory
        for i in range(n_known):
            registers[i, :, i_mem + N_INPUT * i:i_mem + N_INPUT * (i + 1)] = np.eye(N_INPUT)
        Zs = predict_over_delay(Ak, Bk, np.zeros(n_model), Zs,
                                applied_commands(registers, register_schedule(known)))
    # controller output u(k) = C_u x (3, n)
    C_u = np.zeros((N_INPUT, n))
    if cfg.law == "lqr_ff":
        K = LqrLateral(cfg.model_params(), dt, lqr_weights(cfg)).gain(vx)
        X = np.zeros((4, n))       # lqr error state from the (predicted) path-frame state
        X[ErrIdx.E1] = Zs[StateIdx.Y]
        X[ErrIdx.E1_DOT] = Zs[StateIdx.VY] + vx * Zs[StateIdx.PHI]
        X[ErrIdx.E2] = Zs[StateIdx.PHI]
        X[ErrIdx.E2_DOT] = Zs[StateIdx.R]
        C_u[0] = -(K @ X)[0]
    else:
        K = mpc.unconstrained_gain(vx)              # Δu = −K [ζ; u(k−1)]
        Z = np.zeros((n_model + N_INPUT, n))
        Z[:n_model] = Zs
        Z[n_model:, i_mem:i_mem + N_INPUT] = np.eye(N_INPUT)
        C_u = Z[n_model:] - K @ Z                  # u = u(k−1) + Δu
        C_u[~cfg.enabled] = 0.0                     # a disabled input is pinned at 0
    # the command that reaches the actuators: after the delay registers, then the dead time
    A = np.zeros((n, n))
    Bw = np.zeros((n, 1))
    # u(k) enters the first delay register (or the actuators directly)
    def feed(target_rows: slice | None, src: np.ndarray, src_w: np.ndarray) -> None:
        A[target_rows] += src
        Bw[target_rows] += src_w
    w_f = np.zeros((N_INPUT, 1))
    w_f[0, 0] = 1.0                                 # the broken loop injects δ_f here
    C_cmd = C_u.copy()
    C_cmd[0] = 0.0                                  # open loop: δ_f from the injection
    # u applied to the plant this period
    if delay_periods:
        cmd = np.zeros((N_INPUT, n))
        cmd[:, i_del + n_del - 3:i_del + n_del] = np.eye(3)
        cmd_w = np.zeros((N_INPUT, 1))
        # shift register: r0 <- u, r1 <- r0, ...
        feed(slice(i_del, i_del + 3), C_cmd, w_f)
        for j in range(1, delay_periods):
            A[i_del + 3 * j:i_del + 3 * j + 3, i_del + 3 * (j - 1):i_del + 3 * j] = np.eye(3)
    else:
        cmd, cmd_w = C_cmd, w_f
    steer, steer_w = cmd[:2], cmd_w[:2]
    if n_dead:
        feed(slice(i_dead, i_dead + 2), steer, steer_w)
        for j in range(1, n_dead):
            A[i_dead + 2 * j:i_dead + 2 * j + 2, i_dead + 2 * (j - 1):i_dead + 2 * j] = \
                np.eye(2)
        steer = np.zeros((2, n))
        steer[:, i_dead + n_dead_s - 2:i_dead + n_dead_s] = np.eye(2)
        steer_w = np.zeros((2, 1))
    applied = np.vstack([steer, cmd[2:3]])
    applied_w = np.vstack([steer_w, cmd_w[2:3]])
    A[:N_PLANT, :N_PLANT] += Ap
    A[:N_PLANT] += Bp @ applied
    Bw[:N_PLANT] += Bp @ applied_w
    # controller memory: u(k−1) of the next step = the command this step computed, its own
    # output C_u ξ (not the injected δ_f: the break is at the plant's input, the controller's
    # internal states stay closed); older commands shift down the buffer
    A[i_mem:i_mem + N_INPUT] += C_u
    for j in range(N_INPUT, n_mem, N_INPUT):
        A[i_mem + j:i_mem + j + N_INPUT, i_mem + j - N_INPUT:i_mem + j] = np.eye(N_INPUT)
    if obs_A is not None:
        A += obs_A
    A_open = A
    K_f = C_u[0:1]
    A_cl = A_open + Bw @ K_f
    return A_cl, A_open, Bw, K_f


def margins(cfg: MpcConfig, v: VehicleParams, vx: float, **kw: Any) -> Margins:
    """The figures of the module docstring."""
    A_cl, A_o, B_f, K_f = closed_loop(cfg, v, vx, **kw)
    rho, freq = _dominant_pole(A_cl, cfg.dt_s)
    gm, pm, dm = _loop_margins(A_o, B_f, K_f, cfg.dt_s, stable=rho < 1.0)
    return Margins(rho, freq, rho ** (1.0 / cfg.dt_s), gm, pm, vx,
                   None if dm is None else float(dm) * 1e3)


def spectral_radius(cfg: MpcConfig, v: VehicleParams, vx: float, **kw: Any) -> float:
    """``margins(...).spectral_radius`` alone (no frequency sweep): for searches."""
    return _dominant_pole(closed_loop(cfg, v, vx, **kw)[0], cfg.dt_s)[0]


def _dominant_pole(A_cl: np.ndarray, dt: float) -> tuple[float, float]:
    """(ρ, frequency in Hz) of the closed loop's largest pole, the motionless modes left
    out (below)."""
    eig, vec = np.linalg.eig(A_cl)
    # An MPC with more inputs than outputs that penalises only increments has input
    # directions with no motion (a steady yaw moment held by counter-steer front and rear,
    # the car straight): λ = 1 exactly, the vehicle states not in the eigenvector. They do not
    # track anything; the constraints bound them. They are left out of the radius. λ = 1 is a
    # repeated (defective) eigenvalue there, which round-off moves by O(ε^(1/k)) for a block
    # of k (1e-6 with the delay registers, measured), hence 1e-4 on λ; the motion criterion
    # is what tells them apart (a mode that moves the car is never left out).
    motion = np.abs(vec[[VY, R, E2, E1]]).max(axis=0) / np.abs(vec).max(axis=0)
    null = (np.abs(eig - 1.0) < 1e-4) & (motion < 1e-6)
    eig = eig[~null]
    i = int(np.argmax(np.abs(eig)))
    return float(abs(eig[i])), abs(float(np.angle(eig[i]))) / (2.0 * math.pi * dt)


def _loop_margins(A: np.ndarray, B: np.ndarray, K: np.ndarray, dt: float, stable: bool = True
                  ) -> tuple[float | None, float | None, float | None]:
    """(upper GM dB, PM deg, delay margin s) of L(z) = −K (zI − A)⁻¹ B in negative feedback
    (the loop closes with w = K x, i.e. positive feedback of K(zI−A)⁻¹B), on 0.01 rad/s ..
    Nyquist. Gain: over the phase crossovers (L real and negative, at −a) the gain 1/a puts L
    through −1; the gain margin is the smallest such gain above 1. Phase: at each gain
    crossover ω_i (|L| = 1) the phase lag θ_i ∈ [0°, 360°) that puts L on −1,
    θ_i = (arg L + 180°) mod 360°. For a stable loop (``stable``) the phase margin is the
    smallest θ_i, the phase lag that destabilises it first (the poles move continuously
    with the lag, and reach the unit circle exactly where e^{−jθ} L = −1), and the delay
    margin min_i θ_i/ω_i the pure delay at the plant's input that does. (The open loop is
    often unstable here, the MPC's u = u(k−1) + Δu with its front-steer path broken, so a
    lag, not a sign, is what is asked.) For an unstable loop the phase margin is the
    crossover's (arg L + 180°) wrapped to (−180°, 180°] nearest zero, negative when the
    loop is past −1, and there is no delay margin. None where there is no such crossover."""
    w = np.logspace(-2, math.log10(math.pi / dt * 0.999), 6000)
    eye = np.eye(A.shape[0])
    L = np.array([-(K @ np.linalg.solve(np.exp(1j * om * dt) * eye - A, B))[0, 0]
                  for om in w])
    gms, lags = [], []
    for k in range(1, len(w)):
        a, b = L[k - 1], L[k]
        if a.imag * b.imag <= 0.0 and (a.real + b.real) < 0.0:     # crosses the negative axis
            t = a.imag / (a.imag - b.imag) if a.imag != b.imag else 0.0
            gms.append(-20.0 * math.log10(max(abs(a.real + t * (b.real - a.real)), 1e-300)))
        if (abs(a) - 1.0) * (abs(b) - 1.0) <= 0.0 and abs(a) != abs(b):
            # the crossover, interpolated in log |L|
            t = math.log(abs(a)) / (math.log(abs(a)) - math.log(abs(b)))
            om = w[k - 1] + t * (w[k] - w[k - 1])
            ph = math.degrees(math.atan2(a.imag, a.real))
            ph += t * ((math.degrees(math.atan2(b.imag, b.real)) - ph + 180.0) % 360.0 - 180.0)
            lags.append(((ph + 180.0) % 360.0, om))
    upper = min((g for g in gms if g > 0.0), default=None)
    if not lags:
        return upper, None, None
    if stable:
        pm = min(theta for theta, _ in lags)
        dm = min(math.radians(theta) / om for theta, om in lags)
        return upper, pm, dm
    pm = min(((theta + 180.0) % 360.0 - 180.0 for theta, _ in lags), key=abs)
    return upper, pm, None
