"""Models the vehicle: a nonlinear two-track (four-wheel) model with wheel spin, motors, steering.

The plant's vehicle (docs/plant.md, "Vehicle"). Frames and signs follow docs/conventions.md
(ISO 8855: x forward, y left, z up; yaw, yaw rate, yaw moment and steer angles positive to the
left). Wheel order FL, FR, RL, RR (``fourws_common.wheels.Wheel``). The parameters are
:class:`~fourws_sim.core.vehicle_params.VehicleParams` (``vehicle_params.py``).

States (:class:`State`): v_x, v_y, r; X, Y, ψ (continuous, not wrapped); the wheel spin rates
ω_i; per motor the actual torque T_i and its rate Ṫ_i (eq. 32); the actual road-wheel angles
δ_f, δ_r; the two filtered CG accelerations of the load transfer; the transient slip angles α'_i.

Wheel i sits at (x_i, y_i) = (a, +B_f/2), (a, −B_f/2), (−b, +B_r/2), (−b, −B_r/2). Front
wheels steer by δ_f, rear wheels by δ_r (parallel steer, no Ackermann). Contact-point velocity
in the body frame v_i = (v_x − r y_i, v_y + r x_i), rotated into the wheel frame by δ_i;
slips and tyre forces (F_x,i, F_y,i) in the wheel frame from ``tyre.py``; back to the body::

    F_X,i = F_x,i cos δ_i − F_y,i sin δ_i,      F_Y,i = F_x,i sin δ_i + F_y,i cos δ_i

Body dynamics (m includes the wheels; a_x, a_y are the accelerometer-style CG accelerations;
rolling resistance acts on the body, so the reported F_x,i stay the pure tyre forces, and its
tanh makes it vanish smoothly at standstill)::

    m a_x = Σ F_X,i − ½ ρ c_d A v_x|v_x| − f_r m g tanh(v_x / v_rr)
    m a_y = Σ F_Y,i
    v̇_x = a_x + v_y r,   v̇_y = a_y − v_x r
    I_z ṙ = Σ (x_i F_Y,i − y_i F_X,i)
    Ẋ = v_x cos ψ − v_y sin ψ,   Ẏ = v_x sin ψ + v_y cos ψ,   ψ̇ = r
    I_w ω̇_i = T_i − R F_x,i

Vertical loads: quasi-static longitudinal and lateral load transfer from the CG height h,
the lateral part split between the axles by the front share ε of the roll stiffness (roll
centres at ground level, i.e. all lateral transfer goes through the springs)::

    F_z,front axle = m g b/L − m h â_x / L,     F_z,rear axle = m g a/L + m h â_x / L
    ΔF_z,f = ε m h â_y / B_f,                   ΔF_z,r = (1 − ε) m h â_y / B_r
    F_z,FL = F_z,front/2 − ΔF_z,f,  F_z,FR = F_z,front/2 + ΔF_z,f   (likewise rear)

with â_x, â_y the CG accelerations through a first-order lag of time constant
``load_transfer_time_constant_s`` (two states; no algebraic loop between the loads and the
accelerations; in steady state the quasi-static transfer). Loads are clipped at 0 (wheel lift).

Transient lateral slip (Pacejka, "Tire and Vehicle Dynamics", 3rd ed., 2012, §7.2: single
contact point, first-order lag over a rolling distance σ): the tyre force uses the transient
slip angle α'_i in place of the kinematic α_i::

    dα'_i/dt = (α_i − α'_i) max(|v_x,i|, v_min) / σ_i
    σ_i = p_Ty1 R sin(2 atan(F_z,i / (p_Ty2 F_z0)))          (MF 5.2 σ_α0, no camber)

(p_Ty1 the peak of σ over the wheel radius, reached at F_z = p_Ty2 F_z0), σ_i floored at 0.05 m
so the 1 ms RK4 substep resolves the lag at any speed. Longitudinal slip has no lag (σ_κ is a
few centimetres; the wheel-spin mode gives it dynamics). p_Ty1 = 0 turns it off: α'_i are then
held at their initial value and not used.

Numerics: the wheel-spin mode λ ≈ −R² K_κ / (I_w max(|v_x|, v_min)) (K_κ = c_κ F_z) needs
|λ| h < 2.78 for RK4; at h = 1 ms the slip floor ``slip_speed_min_mps`` = 2.5 m/s keeps it
there for loads up to ≈ 2 × static at any speed. Keep the default 1 ms substep (2 ms is at
the edge; from 2.5 ms up the wheel-spin mode rings or diverges at low speed).

:meth:`TwoTrackModel.derivatives` is plain Python floats (numpy's call overhead on 4-element
arrays exceeds the arithmetic), the readable reference: the simulator runs its compiled twin
(``model_jit.py``, the same operations in the same order; a unit test checks they agree) and
``Simulator(jit=False)`` this one.
"""

from __future__ import annotations

import math
from enum import IntEnum
from typing import Any

from fourws_sim.core.tyre import forces_scalar
from fourws_sim.core.vehicle_params import SIGMA_MIN_M, VehicleParams


class State(IntEnum):
    """Indices of the plant state vector."""

    VX = 0
    VY = 1
    R = 2
    X = 3
    Y = 4
    YAW = 5
    OMEGA_FL = 6
    OMEGA_FR = 7
    OMEGA_RL = 8
    OMEGA_RR = 9
    TORQUE_FL = 10
    TORQUE_FR = 11
    TORQUE_RL = 12
    TORQUE_RR = 13
    TORQUE_RATE_FL = 14
    TORQUE_RATE_FR = 15
    TORQUE_RATE_RL = 16
    TORQUE_RATE_RR = 17
    STEER_FRONT = 18
    STEER_REAR = 19
    AX_FILTERED = 20
    AY_FILTERED = 21
    ALPHA_FL = 22
    ALPHA_FR = 23
    ALPHA_RL = 24
    ALPHA_RR = 25


N_STATE = len(State)
OMEGA = slice(State.OMEGA_FL, State.OMEGA_RR + 1)
TORQUE = slice(State.TORQUE_FL, State.TORQUE_RR + 1)
ALPHA = slice(State.ALPHA_FL, State.ALPHA_RR + 1)


class TwoTrackModel:
    """The plant's right-hand side ẏ = f(y, u, μ) in plain floats.

    ``y`` is a sequence in :class:`State` order; ``u`` = (δf_cmd, δr_cmd, T_FL, T_FR, T_RL,
    T_RR) already clipped to the actuator limits; ``mu`` the road μ under each wheel.
    """

    def __init__(self, p: VehicleParams) -> None:
        self.params = p
        m, h, length = p.mass_kg, p.cg_height_m, p.wheelbase_m
        w = m * p.gravity_mps2
        front, rear = p.tyre("front"), p.tyre("rear")
        lim = p.actuator_limits()
        tau_m = p.motor_time_constant_s
        self._c = (
            m, 1.0 / m, 1.0 / p.yaw_inertia_kg_m2,
            p.cg_to_front_axle_m, p.cg_to_rear_axle_m,
            0.5 * p.track_width_front_m, 0.5 * p.track_width_rear_m,
            p.wheel_radius_m, 1.0 / p.wheel_inertia_kg_m2,
            0.5 * w * p.cg_to_rear_axle_m / length,
            0.5 * w * p.cg_to_front_axle_m / length,
            0.5 * m * h / length,
            p.roll_stiffness_front_share * m * h / p.track_width_front_m,
            (1.0 - p.roll_stiffness_front_share) * m * h / p.track_width_rear_m,
            0.5 * p.air_density_kg_m3 * p.drag_coefficient * p.frontal_area_m2,
            p.rolling_resistance_coeff * w, 1.0 / p.rolling_resistance_speed_mps,
            p.slip_speed_min_mps,
            2.0 * tau_m, 1.0 / (2.0 * tau_m * tau_m),
            1.0 / p.steer_front_time_constant_s, lim.max_steer_rate_front_rad_s,
            1.0 / p.steer_rear_time_constant_s, lim.max_steer_rate_rear_rad_s,
            1.0 / p.load_transfer_time_constant_s,
        )
        self._relax = (p.tyre_relaxation_peak_over_radius * p.wheel_radius_m,
                       1.0 / (p.tyre_relaxation_load_factor * p.tyre_nominal_load_n))
        self._kf = front.scalar_constants(front.cornering_coeff)
        self._kr = rear.scalar_constants(rear.cornering_coeff)

    def constants(self) -> tuple[float, ...]:
        """Every constant :meth:`derivatives` uses, flat: the model's own 25, the relaxation
        pair (peak σ, 1/(p_Ty2 F_z0)), :data:`SIGMA_MIN_M`, then the front and the rear tyre's
        ``scalar_constants`` (11 each). The layout ``model_jit`` (the compiled twin) reads."""
        return (*self._c, *self._relax, SIGMA_MIN_M, *self._kf, *self._kr)

    def derivatives(
        self,
        y: list[float] | tuple[float, ...],
        u: tuple[float, ...],
        mu: tuple[float, float, float, float],
        info: dict[str, Any] | None = None,
    ) -> list[float]:
        """ẏ (list in :class:`State` order). With ``info`` given, also stores the wheel-frame
        tyre forces ``fx``, ``fy``, loads ``fz`` (tuples of 4) and the CG accelerations
        ``ax``, ``ay`` (accelerometer-style, body frame) in it."""
        (m, inv_m, inv_iz, a, b, hf, hr, rad, inv_iw, fz_f0, fz_r0, k_long, k_lat_f, k_lat_r,
         k_aero, f_rr, inv_v_rr, v_min, two_tau, inv_two_tau2, inv_tau_f, rate_f, inv_tau_r,
         rate_r, inv_tau_lt) = self._c
        (vx, vy, r, _x, _y, yaw, w0, w1, w2, w3, t0, t1, t2, t3, dt0, dt1, dt2, dt3,
         df, dr, axf, ayf, al0, al1, al2, al3) = y
        df_cmd, dr_cmd, tc0, tc1, tc2, tc3 = u
        mu0, mu1, mu2, mu3 = mu
        forces = _tyre_forces
        kf, kr = self._kf, self._kr
        atan = math.atan

        dlong = k_long * axf
        fzf, fzr = fz_f0 - dlong, fz_r0 + dlong
        dlf, dlr = k_lat_f * ayf, k_lat_r * ayf
        fz0 = max(fzf - dlf, 0.0)
        fz1 = max(fzf + dlf, 0.0)
        fz2 = max(fzr - dlr, 0.0)
        fz3 = max(fzr + dlr, 0.0)

        # wheel-frame contact velocities, slip denominators and slip angles (tyre.slips)
        cf, sf = math.cos(df), math.sin(df)
        cr, sr = math.cos(dr), math.sin(dr)
        vyf, vyr = vy + a * r, vy - b * r
        vxl, vxr = vx - hf * r, vx + hf * r
        vx0, vy0 = vxl * cf + vyf * sf, vyf * cf - vxl * sf
        vx1, vy1 = vxr * cf + vyf * sf, vyf * cf - vxr * sf
        vxl, vxr = vx - hr * r, vx + hr * r
        vx2, vy2 = vxl * cr + vyr * sr, vyr * cr - vxl * sr
        vx3, vy3 = vxr * cr + vyr * sr, vyr * cr - vxr * sr
        n0 = vx0 if vx0 > v_min else (-vx0 if -vx0 > v_min else v_min)
        n1 = vx1 if vx1 > v_min else (-vx1 if -vx1 > v_min else v_min)
        n2 = vx2 if vx2 > v_min else (-vx2 if -vx2 > v_min else v_min)
        n3 = vx3 if vx3 > v_min else (-vx3 if -vx3 > v_min else v_min)
        a0, a1, a2, a3 = -atan(vy0 / n0), -atan(vy1 / n1), -atan(vy2 / n2), -atan(vy3 / n3)
        s_peak, inv_fz_s = self._relax
        if s_peak > 0.0:
            s0 = max(s_peak * math.sin(2.0 * atan(fz0 * inv_fz_s)), SIGMA_MIN_M)
            s1 = max(s_peak * math.sin(2.0 * atan(fz1 * inv_fz_s)), SIGMA_MIN_M)
            s2 = max(s_peak * math.sin(2.0 * atan(fz2 * inv_fz_s)), SIGMA_MIN_M)
            s3 = max(s_peak * math.sin(2.0 * atan(fz3 * inv_fz_s)), SIGMA_MIN_M)
            dal = ((a0 - al0) * n0 / s0, (a1 - al1) * n1 / s1,
                   (a2 - al2) * n2 / s2, (a3 - al3) * n3 / s3)
            u0, u1, u2, u3 = al0, al1, al2, al3
        else:
            dal = (0.0, 0.0, 0.0, 0.0)
            u0, u1, u2, u3 = a0, a1, a2, a3
        fx0, fy0 = forces(vx0, n0, u0, w0 * rad, fz0, mu0, kf)
        fx1, fy1 = forces(vx1, n1, u1, w1 * rad, fz1, mu1, kf)
        fx2, fy2 = forces(vx2, n2, u2, w2 * rad, fz2, mu2, kr)
        fx3, fy3 = forces(vx3, n3, u3, w3 * rad, fz3, mu3, kr)

        fxb_f0, fxb_f1 = fx0 * cf - fy0 * sf, fx1 * cf - fy1 * sf
        fyb_f = (fx0 + fx1) * sf + (fy0 + fy1) * cf
        fxb_r2, fxb_r3 = fx2 * cr - fy2 * sr, fx3 * cr - fy3 * sr
        fyb_r = (fx2 + fx3) * sr + (fy2 + fy3) * cr

        ax = (fxb_f0 + fxb_f1 + fxb_r2 + fxb_r3 - k_aero * vx * abs(vx)
              - f_rr * math.tanh(vx * inv_v_rr)) * inv_m
        ay = (fyb_f + fyb_r) * inv_m
        mz = a * fyb_f - b * fyb_r + hf * (fxb_f1 - fxb_f0) + hr * (fxb_r3 - fxb_r2)
        cy, sy = math.cos(yaw), math.sin(yaw)

        rate = (df_cmd - df) * inv_tau_f
        ddf = rate_f if rate > rate_f else (-rate_f if rate < -rate_f else rate)
        rate = (dr_cmd - dr) * inv_tau_r
        ddr = rate_r if rate > rate_r else (-rate_r if rate < -rate_r else rate)

        if info is not None:
            info["fx"] = (fx0, fx1, fx2, fx3)
            info["fy"] = (fy0, fy1, fy2, fy3)
            info["fz"] = (fz0, fz1, fz2, fz3)
            info["ax"] = ax
            info["ay"] = ay
            info["alpha"] = (a0, a1, a2, a3)
        return [
            ax + vy * r,
            ay - vx * r,
            mz * inv_iz,
            vx * cy - vy * sy,
            vx * sy + vy * cy,
            r,
            (t0 - rad * fx0) * inv_iw,
            (t1 - rad * fx1) * inv_iw,
            (t2 - rad * fx2) * inv_iw,
            (t3 - rad * fx3) * inv_iw,
            dt0, dt1, dt2, dt3,
            (tc0 - t0 - two_tau * dt0) * inv_two_tau2,
            (tc1 - t1 - two_tau * dt1) * inv_two_tau2,
            (tc2 - t2 - two_tau * dt2) * inv_two_tau2,
            (tc3 - t3 - two_tau * dt3) * inv_two_tau2,
            ddf,
            ddr,
            (ax - axf) * inv_tau_lt,
            (ay - ayf) * inv_tau_lt,
            *dal,
        ]


def _tyre_forces(
    vxw: float, den: float, alpha: float, omega_r: float, fz: float, mu: float,
    k: tuple[float, ...],
) -> tuple[float, float]:
    """Combined-slip forces of one wheel in plain floats from its wheel-frame forward
    velocity ``vxw``, slip denominator ``den`` = max(|vxw|, v_min), slip angle ``alpha``
    (rad, tyre.slips sign) and rim speed ``omega_r``: the slip ratio of ``tyre.slips``, then
    :func:`fourws_sim.core.tyre.forces_scalar`."""
    return forces_scalar((omega_r - vxw) / den, alpha, fz, mu, k)
