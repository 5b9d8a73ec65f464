"""Computes the total driving force from the speed error: the longitudinal speed PID, eq. (24).

The paper writes the continuous law (eq. 24; docs/lower-layer.md, "Speed PID")

    F_x = K_p e + K_i ∫ e dt + K_d de/dt,      e = v_ref − v,

and leaves the gains, the discretisation and the actuator limits open. Implemented here,
at a fixed step ``dt_s`` supplied by the caller (no clock is read):

    P_k  = K_p e_k
    D_k  = −K_d ḋ_k,   ḋ_k = ḋ_{k−1} + (Δv_k/dt − ḋ_{k−1}) dt/(T_f + dt), the backward Euler
           of s/(T_f s + 1) on the *measured* speed: a step of the reference gives no
           derivative kick (for a constant reference de/dt = −dv/dt)
    FF_k = m a_ref    (optional feed-forward of the reference acceleration; zero when the
           reference speed is constant)
    I_k  = integral term in newtons (K_i is inside the state, so a gain change is
           bumpless), forward-Euler: I_{k+1} = I_k + K_i e_k dt (+ anti-windup, below)
    F_k  = sat(P_k + I_k + D_k + FF_k, F_min, F_max),  F_max = T_max,total / r,
           F_min = T_min,total / r, T_k = F_k r (the total wheel torque of the four motors).

Anti-windup (``anti_windup``):
    "conditional"      the integrator is frozen on a step where the output is saturated and
                       the error pushes further into that limit (clamping); in addition the
                       integral term itself is kept inside [F_min, F_max].
    "back_calculation" I_{k+1} = I_k + K_i e_k dt + min(dt/T_t, 1)(F_k − u_k), u_k the
                       unsaturated output, T_t = ``tracking_time_s`` (the min keeps the
                       discrete update stable if T_t < dt); integral kept in [F_min, F_max].
    "none"             plain integration (kept for comparison in tests and studies only).

Default gains (m = 750 kg): K_p = 1500 N/(m/s) and K_i = 750 N/m (ω_n = 1 rad/s, ζ = 1 on the
integrator plant 1/(m s)), crossover ≈ 2.2 rad/s, ≈ 70° phase margin after the motor lag and the
one-sample delay, gain margin > 20 dB; a 300 N disturbance (cornering drag in a lane change)
costs about 0.15 m/s. K_d = 0 (derivative action on the speed is acceleration feedback, which
only adds apparent mass and passes wheel-speed noise); the term is there for eq. (24)'s form and
can be switched on from the YAML. Default anti-windup: back-calculation with T_t = 0.1 s
(≪ T_i = K_p/K_i = 2 s); a +30 km/h step from 60 km/h overshoots 0.3 % of the step and settles
(2 %) in 2.3 s. A small unsaturated step overshoots ≈ 14 % whatever the anti-windup (a type-2
loop), so speed references should change as ramps with ``a_ref_mps2`` as feed-forward.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from fourws_common.params import param
from fourws_common.vehicle_info import field_range

ANTI_WINDUP_CHOICES = ("conditional", "back_calculation", "none")


@dataclass(frozen=True)
class SpeedPidConfig:
    """Gains, filter and limits of the speed PID (SI units)."""

    kp: float = param(1500.0, "proportional gain on the speed error", lo=0.0, hi=1.0e6,
                      unit="N/(m/s)")
    ki: float = param(750.0, "integral gain on the speed error", lo=0.0, hi=1.0e6, unit="N/m")
    kd: float = param(0.0, "derivative gain, acting on the filtered measured speed",
                      lo=0.0, hi=1.0e5, unit="N/(m/s^2)")
    derivative_filter_tau_s: float = param(
        0.05, "time constant of the first-order filter on the measured-speed derivative",
        lo=0.0, hi=10.0, unit="s")
    anti_windup: str = param("back_calculation", "integrator anti-windup scheme",
                             choices=ANTI_WINDUP_CHOICES)
    tracking_time_s: float = param(0.1, "back-calculation tracking time constant T_t",
                                   lo=1.0e-3, hi=100.0, unit="s")
    max_total_torque_nm: float = param(2000.0, "upper limit of the total wheel torque "
                                       "(sum of the four motors' limits)", lo=0.0, hi=1.0e5,
                                       unit="N*m")
    min_total_torque_nm: float = param(-2000.0, "lower limit of the total wheel torque "
                                       "(regenerative braking)", lo=-1.0e5, hi=0.0,
                                       unit="N*m")
    wheel_radius_m: float = param(0.27, "effective rolling radius", **field_range("wheel_radius_m"))
    mass_kg: float = param(750.0, "vehicle mass, for the acceleration feed-forward",
                           **field_range("mass_kg"))
    accel_feedforward: bool = param(True, "add m * a_ref to the PID force")

    def __post_init__(self) -> None:
        if not self.min_total_torque_nm < self.max_total_torque_nm:
            raise ValueError(
                "min_total_torque_nm, max_total_torque_nm: need min < max, got "
                f"{self.min_total_torque_nm} and {self.max_total_torque_nm}")

    @property
    def max_force_n(self) -> float:
        """Largest total driving force the motors can give (N)."""
        return self.max_total_torque_nm / self.wheel_radius_m

    @property
    def min_force_n(self) -> float:
        """Most negative total force the motors can give (N)."""
        return self.min_total_torque_nm / self.wheel_radius_m


@dataclass(frozen=True, slots=True)
class PidOutput:
    """One PID step: total force (N), total wheel torque (N·m), saturation flag and terms."""

    force_n: float
    torque_nm: float
    saturated: bool
    p_n: float = 0.0
    i_n: float = 0.0
    d_n: float = 0.0
    ff_n: float = 0.0


class SpeedPid:
    """Discrete speed PID of eq. (24) with anti-windup; state is the integral and filter."""

    def __init__(self, cfg: SpeedPidConfig | None = None) -> None:
        self.cfg = cfg if cfg is not None else SpeedPidConfig()
        self._integral_n = 0.0
        self._v_prev: float | None = None
        self._dv_filt = 0.0
        self.reset()

    @property
    def integral_n(self) -> float:
        """The integral term's current value (N)."""
        return self._integral_n

    def reset(self, integral_n: float = 0.0) -> None:
        """Clear the state; ``integral_n`` presets the integral term (N), e.g. the road load
        at the initial speed for a bumpless start."""
        if not math.isfinite(integral_n):
            raise ValueError(f"SpeedPid.reset: integral_n must be finite, got {integral_n!r}")
        self._integral_n = float(integral_n)
        self._v_prev = None
        self._dv_filt = 0.0

    def step(self, v_ref_mps: float, v_mps: float, dt_s: float,
             a_ref_mps2: float = 0.0) -> PidOutput:
        """Advance one period.

        v_ref_mps, v_mps: reference and measured longitudinal speed (m/s); dt_s: period (s),
        > 0; a_ref_mps2: reference acceleration (m/s²) for the feed-forward. Raises
        ``ValueError`` on a non-finite input, a non-positive period or inputs whose products
        overflow; the state is then left unchanged.
        """
        for name, val in (("v_ref_mps", v_ref_mps), ("v_mps", v_mps), ("dt_s", dt_s),
                          ("a_ref_mps2", a_ref_mps2)):
            if not math.isfinite(val):
                raise ValueError(f"SpeedPid.step: {name} must be finite, got {val!r}")
        if dt_s <= 0.0:
            raise ValueError(f"SpeedPid.step: dt_s must be positive, got {dt_s!r}")
        cfg = self.cfg
        f_max = cfg.max_force_n
        f_min = cfg.min_force_n

        e = v_ref_mps - v_mps
        if self._v_prev is None:
            dv_filt = 0.0
        else:
            raw = (v_mps - self._v_prev) / dt_s
            dv_filt = self._dv_filt + (raw - self._dv_filt) * dt_s / (
                cfg.derivative_filter_tau_s + dt_s)
        p = cfg.kp * e
        d = -cfg.kd * dv_filt
        ff = cfg.mass_kg * a_ref_mps2 if cfg.accel_feedforward else 0.0
        i = self._integral_n
        u = p + i + d + ff
        force = min(max(u, f_min), f_max)
        saturated = u > f_max or u < f_min

        aw = cfg.anti_windup
        if aw == "conditional":
            pushing = (u > f_max and e > 0.0) or (u < f_min and e < 0.0)
            i_next = i if pushing else i + cfg.ki * e * dt_s
            i_next = min(max(i_next, f_min), f_max)
        elif aw == "back_calculation":
            k_aw = min(dt_s / cfg.tracking_time_s, 1.0)
            i_next = i + cfg.ki * e * dt_s + k_aw * (force - u)
            i_next = min(max(i_next, f_min), f_max)
        else:
            i_next = i + cfg.ki * e * dt_s

        if not all(math.isfinite(v) for v in (u, force, i_next, dv_filt)):
            # finite inputs whose products overflow (v = 1e308): never commit them
            raise ValueError(f"SpeedPid.step: inputs v_ref={v_ref_mps!r}, v={v_mps!r}, "
                             f"dt={dt_s!r} overflow the law; state left unchanged")
        self._integral_n = i_next
        self._v_prev = float(v_mps)
        self._dv_filt = dv_filt
        return PidOutput(force_n=force, torque_nm=force * cfg.wheel_radius_m,
                         saturated=saturated, p_n=p, i_n=i, d_n=d, ff_n=ff)
