"""Evaluates the plant's right-hand side compiled: ``TwoTrackModel.derivatives`` in numba.

The equations, symbols and signs are those of ``vehicle.py``'s module docstring, with the
combined-slip tyre of ``tyre.py`` (:func:`tyre.forces_scalar`); docs/plant.md, "Simulator".
Every value is computed with the operations of the plain-float code in the same order,
``fastmath`` off, so the compiled results equal the readable reference (in practice bit for
bit; both call the C library's transcendental functions). ``TwoTrackModel.derivatives`` and
``tyre.forces_scalar`` stay the reference: tests/unit/test_sim_compiled.py compares them.

Two things differ from the plain-float code, neither in the values:

* the four wheels' transcendental functions are evaluated layer by layer (the four slip
  angles' atan, then the four relaxation lengths' atan, then their sin, ...) instead of
  wheel by wheel, so the CPU overlaps the four independent calls;
* divisions follow numpy's error model (no ``ZeroDivisionError``). No divisor can be zero
  for a finite state: slip denominators are floored at v_min > 0, σ at ``SIGMA_MIN_M``, the
  tyre divides by D > 0 and ρ ≥ 1e-12 (the lifted wheel's and the zero-slip branch's values
  are computed but not used, as in ``forces_scalar``'s early returns).

Arrays instead of tuples: the state ``y`` (26,) in ``vehicle.State`` order, the command
``u`` (6,) = (δf_cmd, δr_cmd, T_FL, T_FR, T_RL, T_RR) already clipped, the road ``mu`` (4,),
the constants ``c`` of :func:`model_constants` (built once per vehicle) and the wheel table
``wt`` (:data:`N_ROWS`, 4): per-wheel quantities, one row each (``FZ``, ``FX``, ...),
columns FL FR RL RR; scratch and outputs (loads, forces, slip angles) of one evaluation.
Compiled with ``cache=True`` (machine code on disk: ``__pycache__`` or ``NUMBA_CACHE_DIR``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from fourws_sim.core.vehicle import TwoTrackModel

_jit = numba.njit(cache=True, fastmath=False, error_model="numpy")

# layout of the constants array: the model's own constants (TwoTrackModel.constants order) ...
(M, INV_M, INV_IZ, A, B, HF, HR, RAD, INV_IW, FZ_F0, FZ_R0, K_LONG, K_LAT_F, K_LAT_R,
 K_AERO, F_RR, INV_V_RR, V_MIN, TWO_TAU, INV_TWO_TAU2, INV_TAU_F, RATE_F, INV_TAU_R,
 RATE_R, INV_TAU_LT) = range(25)
# ... the relaxation length (peak σ, 1/(p_Ty2 F_z0)) and its floor ...
S_PEAK, INV_FZ_S, SIGMA_MIN = 25, 26, 27
# ... the front and rear tyres' scalar constants (TyreCoefficients.scalar_constants) ...
TYRE_FRONT, TYRE_REAR = 28, 39
(KY1_FZ0, INV_KY2_FZ0, P_D2, INV_FZ0, C_KX, CY, EY, UY, CX, EX, UX) = range(11)
# ... and, appended here, each wheel's position (x_i, y_i) in the body frame, m
WHEEL_X, WHEEL_Y = 50, 54
N_CONSTANTS = 58

# rows of the wheel table
(FZ, VXW, VYW, DEN, ALPHA, SLIP, KAPPA, FX, FY,  # loads, wheel-frame velocities, slips, forces
 T1, T2, T3, T4, D, SX, SY, RHO) = range(17)  # scratch
N_ROWS = 17


def model_constants(model: TwoTrackModel) -> np.ndarray:
    """The constants array (float64, :data:`N_CONSTANTS`) of ``model``: exactly the floats
    its plain-Python :meth:`~TwoTrackModel.derivatives` uses, then the wheel positions."""
    a, b, hf, hr = (model.constants()[i] for i in (A, B, HF, HR))
    c = np.array((*model.constants(), a, a, -b, -b, hf, -hf, hr, -hr), dtype=np.float64)
    if c.shape != (N_CONSTANTS,):
        raise ValueError(f"model constants: expected {N_CONSTANTS}, got {c.shape}")
    return c


def wheel_table() -> np.ndarray:
    """A fresh wheel table for :func:`derivatives` and :func:`tyre_forces`."""
    return np.zeros((N_ROWS, 4))


@_jit
def _tyre(i: int) -> int:
    """Offset in the constants of wheel ``i``'s tyre (FL, FR front; RL, RR rear)."""
    return TYRE_FRONT if i < 2 else TYRE_REAR


@_jit
def tyre_forces(wt: np.ndarray, mu: np.ndarray, c: np.ndarray) -> None:
    """:func:`fourws_sim.core.tyre.forces_scalar` of the four wheels: from the rows ``KAPPA``
    (slip ratio), ``SLIP`` (slip angle, rad) and ``FZ`` (load, N) of the wheel table and the
    road ``mu`` into its rows ``FX``, ``FY`` (wheel frame, N); layer by layer over the
    wheels (see the module docstring)."""
    for i in range(4):
        k = _tyre(i)
        fz = wt[FZ, i]
        lam = 1.0 + c[k + P_D2] * (fz * c[k + INV_FZ0] - 1.0)
        lam = 1.0 if lam > 1.0 else (0.1 if lam < 0.1 else lam)
        wt[D, i] = mu[i] * fz * lam
        wt[T1, i] = math.atan(fz * c[k + INV_KY2_FZ0])
    for i in range(4):
        k = _tyre(i)
        fz = wt[FZ, i]
        d = wt[D, i]
        k_a = c[k + KY1_FZ0] * math.sin(2.0 * wt[T1, i])  # K_α(F_z)
        sx = wt[KAPPA, i] * c[k + C_KX] * fz / (c[k + UX] * c[k + CX] * d)
        sy = wt[SLIP, i] * k_a / (c[k + UY] * c[k + CY] * d)
        wt[SX, i] = sx
        wt[SY, i] = sy
        wt[RHO, i] = math.sqrt(sx * sx + sy * sy)
    # Magic Formula shape over ρ: g = sin(C atan(u − E (u − atan u))) / ρ, u = ρ u*
    for i in range(4):
        k = _tyre(i)
        wt[T1, i] = math.atan(wt[RHO, i] * c[k + UX])
        wt[T2, i] = math.atan(wt[RHO, i] * c[k + UY])
    for i in range(4):
        k = _tyre(i)
        u = wt[RHO, i] * c[k + UX]
        wt[T3, i] = math.atan(u - c[k + EX] * (u - wt[T1, i]))
        u = wt[RHO, i] * c[k + UY]
        wt[T4, i] = math.atan(u - c[k + EY] * (u - wt[T2, i]))
    for i in range(4):
        k = _tyre(i)
        d, sx, sy, rho = wt[D, i], wt[SX, i], wt[SY, i], wt[RHO, i]
        if d <= 0.0:
            wt[FX, i] = 0.0
            wt[FY, i] = 0.0
        elif rho < 1e-12:
            wt[FX, i] = d * sx * c[k + CX] * c[k + UX]
            wt[FY, i] = d * sy * c[k + CY] * c[k + UY]
        else:
            gx = math.sin(c[k + CX] * wt[T3, i]) / rho
            gy = math.sin(c[k + CY] * wt[T4, i]) / rho
            wt[FX, i] = d * sx * gx
            wt[FY, i] = d * sy * gy


@_jit
def _floor(value: float, lo: float) -> float:
    """Python's ``max(value, lo)`` (``value`` kept unless ``lo`` is greater, NaN kept)."""
    return lo if lo > value else value


@_jit
def _sat(rate: float, lim: float) -> float:
    return lim if rate > lim else (-lim if rate < -lim else rate)


@_jit
def derivatives(
    y: np.ndarray, u: np.ndarray, mu: np.ndarray, c: np.ndarray, dy: np.ndarray,
    wt: np.ndarray,
) -> tuple[float, float]:
    """ẏ of ``TwoTrackModel.derivatives`` into ``dy`` (26,); returns the CG accelerations
    (a_x, a_y) and leaves the loads, wheel-frame tyre forces and kinematic slip angles in
    the rows ``FZ``, ``FX``, ``FY``, ``ALPHA`` of the wheel table ``wt``."""
    inv_m = c[INV_M]
    a = c[A]
    b = c[B]
    hf = c[HF]
    hr = c[HR]
    rad = c[RAD]
    v_min = c[V_MIN]

    vx = y[0]
    vy = y[1]
    r = y[2]
    df = y[18]
    dr = y[19]
    axf = y[20]
    ayf = y[21]

    # vertical loads: lagged load transfer, clipped at 0 (wheel lift)
    dlong = c[K_LONG] * axf
    fzf = c[FZ_F0] - dlong
    fzr = c[FZ_R0] + dlong
    dlf = c[K_LAT_F] * ayf
    dlr = c[K_LAT_R] * ayf
    wt[FZ, 0] = _floor(fzf - dlf, 0.0)
    wt[FZ, 1] = _floor(fzf + dlf, 0.0)
    wt[FZ, 2] = _floor(fzr - dlr, 0.0)
    wt[FZ, 3] = _floor(fzr + dlr, 0.0)

    # wheel-frame contact velocities v_i = (v_x − r y_i, v_y + r x_i) turned by δ_i, slip
    # denominators max(|v_x,i|, v_min) and kinematic slip angles (tyre.slips)
    cf = math.cos(df)
    sf = math.sin(df)
    cr = math.cos(dr)
    sr = math.sin(dr)
    for i in range(4):
        cd, sd = (cf, sf) if i < 2 else (cr, sr)
        vxb = vx - c[WHEEL_Y + i] * r
        vyb = vy + c[WHEEL_X + i] * r
        vxw = vxb * cd + vyb * sd
        wt[VXW, i] = vxw
        wt[VYW, i] = vyb * cd - vxb * sd
        wt[DEN, i] = vxw if vxw > v_min else (-vxw if -vxw > v_min else v_min)
    # transient slip angles (relaxation length σ_i); p_Ty1 = 0: off, kinematic α used
    s_peak = c[S_PEAK]
    relax = s_peak > 0.0
    for i in range(4):
        wt[ALPHA, i] = -math.atan(wt[VYW, i] / wt[DEN, i])
        if relax:
            wt[T1, i] = math.atan(wt[FZ, i] * c[INV_FZ_S])
    if relax:
        for i in range(4):
            sigma = _floor(s_peak * math.sin(2.0 * wt[T1, i]), c[SIGMA_MIN])
            dy[22 + i] = (wt[ALPHA, i] - y[22 + i]) * wt[DEN, i] / sigma
            wt[SLIP, i] = y[22 + i]
    else:
        for i in range(4):
            dy[22 + i] = 0.0
            wt[SLIP, i] = wt[ALPHA, i]

    # tyre forces, wheel frame; slip ratio κ = (ω R − v_x,i) / den (vehicle._tyre_forces)
    for i in range(4):
        wt[KAPPA, i] = (y[6 + i] * rad - wt[VXW, i]) / wt[DEN, i]
    tyre_forces(wt, mu, c)
    fx0, fx1, fx2, fx3 = wt[FX, 0], wt[FX, 1], wt[FX, 2], wt[FX, 3]
    fy0, fy1, fy2, fy3 = wt[FY, 0], wt[FY, 1], wt[FY, 2], wt[FY, 3]

    # to the body frame; CG accelerations and yaw moment
    fxb_f0 = fx0 * cf - fy0 * sf
    fxb_f1 = fx1 * cf - fy1 * sf
    fyb_f = (fx0 + fx1) * sf + (fy0 + fy1) * cf
    fxb_r2 = fx2 * cr - fy2 * sr
    fxb_r3 = fx3 * cr - fy3 * sr
    fyb_r = (fx2 + fx3) * sr + (fy2 + fy3) * cr

    ax = (fxb_f0 + fxb_f1 + fxb_r2 + fxb_r3 - c[K_AERO] * vx * abs(vx)
          - c[F_RR] * math.tanh(vx * c[INV_V_RR])) * inv_m
    ay = (fyb_f + fyb_r) * inv_m
    mz = a * fyb_f - b * fyb_r + hf * (fxb_f1 - fxb_f0) + hr * (fxb_r3 - fxb_r2)
    cy = math.cos(y[5])
    sy = math.sin(y[5])

    dy[0] = ax + vy * r
    dy[1] = ay - vx * r
    dy[2] = mz * c[INV_IZ]
    dy[3] = vx * cy - vy * sy
    dy[4] = vx * sy + vy * cy
    dy[5] = r
    for i in range(4):
        # wheel spin I_w ω̇ = T − R F_x; motors, eq. (32): d/dt [T, Ṫ] = [Ṫ, (T_cmd − T − 2τ Ṫ)
        # / (2τ²)]
        dy[6 + i] = (y[10 + i] - rad * wt[FX, i]) * c[INV_IW]
        dy[10 + i] = y[14 + i]
        dy[14 + i] = (u[2 + i] - y[10 + i] - c[TWO_TAU] * y[14 + i]) * c[INV_TWO_TAU2]
    # steering actuators: first-order lag with a rate limit
    dy[18] = _sat((u[0] - df) * c[INV_TAU_F], c[RATE_F])
    dy[19] = _sat((u[1] - dr) * c[INV_TAU_R], c[RATE_R])
    # load-transfer lag
    dy[20] = (ax - axf) * c[INV_TAU_LT]
    dy[21] = (ay - ayf) * c[INV_TAU_LT]
    return ax, ay
