"""Distributes the total wheel torque T and the yaw moment M_z over four in-wheel motors.

The paper's eq. (25)-(31) and beyond (docs/lower-layer.md, "Allocation"). Wheel order FL, FR,
RL, RR (``fourws_common.wheels.Wheel``). ISO 8855 signs: positive M_z turns the car left
(counter-clockwise seen from above), so the right wheels carry more drive torque. With equal
front and rear track B and wheel radius r the two demands are, eq. (27),

    T_fl + T_fr + T_rl + T_rr = T
    (B/2r)(−T_fl + T_fr − T_rl + T_rr) = M_z,

which are equivalent to prescribing the two side sums

    S_L = T_fl + T_rl = T/2 − M_z r/B,      S_R = T_fr + T_rr = T/2 + M_z r/B.

``optimal`` — the paper's method, eq. (26)-(31), corrected
    Minimise J = Σ F_xi²/(μ_i F_zi)², F_xi = T_i/r (eq. 26; μ_i is the paper's τ_i, the
    road adhesion under wheel i). With c_i = μ_i F_zi the Lagrangian
    J + λ_1(Σ T_i − T) + λ_2((B/2r)Σ s_i T_i − M_z), s_i = −1 left / +1 right, is
    stationary at T_i = −(r c_i)²(λ_1 + s_i λ_2 B/2r)/2, the unique minimum (J is a
    positive-definite diagonal quadratic): on each side the torque is split in proportion to
    c_i². With the side sums above (eq. 28, corrected):

        T_rl = (T/2 − M_z r/B) c_rl² / (c_fl² + c_rl²),   T_fl = T/2 − M_z r/B − T_rl
        T_rr = (T/2 + M_z r/B) c_rr² / (c_fr² + c_rr²),   T_fr = T/2 + M_z r/B − T_rr

    What the paper prints wrongly (docs/deviations.md, 4-5): eq. (28)'s second line reads
    T_fr = T/2 − M_z r/B − T_rr, where eq. (27) gives "+ M_z r/B" (eq. (29) and eq. (31)'s
    T_rr numerator inherit the sign); eq. (30)'s first denominator is the front wheel's
    (μ_fl F_zfl r)² (resp. right), not the rear wheel's (as printed ∂J/∂T_rl = 0 gives
    T_rl = S_L/2 whatever the loads); eq. (31)'s denominators read μ_rl²F_zrl² + μ_rl²F_zrl²
    and are μ_fl²F_zfl² + μ_rl²F_zrl² (resp. right). Implemented as above.
    Each wheel's torque is then clipped to ±motor_torque_max_nm and the shortfall reported.

``optimal_bounded`` — beyond the paper
    The same objective with |T_i| ≤ b_i, b_i = min(T_motor,max, r √max((μ_i F_zi)² − F_yi², 0)):
    the motor limit and the friction circle's room left by the tyre's lateral force (eq. 25
    with η_i ≤ 1). The achievable side sums form the rectangle |S_L| ≤ b_fl + b_rl,
    |S_R| ≤ b_fr + b_rr; a demand outside it is served by ``priority``, lexicographically and
    exactly, each stage a 1-D projection onto an interval:
      "yaw_moment":   D = S_R − S_L = 2 M_z r/B as close to its demand as the rectangle
                      allows, then, with D fixed, T = 2 S_L + D as close to its demand;
      "total_torque": T = S_L + S_R first, then D with T fixed.
    The tyre-usage QP with these achievable (T*, M_z*) as hard equalities is then always
    feasible. It is solved by OSQP (``bounded_solver = "osqp"``, ``bounded_qp``; a side at
    the edge of its range is fixed beforehand, so the QP is never degenerate, and the side-sum
    residual (~1e-13) goes to the wheel with the most room) or by the exact per-side closed
    form (``"analytic"``: split ∝ c_i², the wheel that breaks its bound pinned at it, its side
    partner taking the rest). If OSQP does not report "solved" with a successful polish, the
    analytic solution is used and the status says "solver_fallback" (the two agree to
    ~1e-11 N·m, unit tests). The unmet parts T − T_achieved and M_z − M_z,achieved are
    reported.

``rule`` — the ablation's conventional baseline: each side sum split equally front/rear,
T_fl = T_rl = S_L/2, T_fr = T_rr = S_R/2 (left/right difference ΔT per side = M_z r/B),
clipped to the motor limits.

``equal`` — T/4 per wheel (controllers without DYC), clipped to the motor limits.

``production`` — what a car already does (the fair baseline, beyond the paper): each side sum
split between the axles by static axle load (front share b/L) when it drives (S ≥ 0) and by
the production brake balance ``brake_balance_front`` when it brakes (S < 0); clipped to the
motor limits.

Wheels in the air: a wheel with F_z ≤ min_fz_n (or μ_i F_zi below 1e-3 N) can transmit no
force: zero weight in ``optimal`` (its side partner takes the whole side sum), a zero bound
in ``optimal_bounded``; with both wheels of a side in the air that side's sum is unmet and
reported. ``rule`` and ``equal`` do not use the loads. Nothing divides by F_z.

Inputs are validated: non-finite numbers, a wrong shape, μ outside [0, 3], |F_z| or |F_y|
above 1e6 N, |T| above demand_sanity_factor × 4 T_motor,max or |M_z| above
demand_sanity_factor × 2 B T_motor,max / r raise ``ValueError``. Outputs are always finite.
Status strings: "ok", or a comma-separated subset, in this order, of "limited" (some demand
unmet beyond 1e-9 relative), "wheel_lift" (some wheel's load at or below min_fz_n, reported
by every method) and "solver_fallback" (see above); :class:`TorqueAllocator` appends
"slip_limited" when its slip limiter cut a wheel's torque.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fourws_common.params import param
from fourws_common.vehicle_info import field_range
from fourws_common.wheels import Wheel
from fourws_torque_alloc.core.bounded_qp import BoundedQp
from fourws_torque_alloc.core.bounded_qp import clip_scalar as _clip
from fourws_torque_alloc.core.slip_control import WheelMotion, limit_slip

METHODS = ("optimal", "optimal_bounded", "rule", "equal", "production")
PRIORITIES = ("yaw_moment", "total_torque")
BOUNDED_SOLVERS = ("osqp", "analytic")
#: where the per-wheel F_z, F_y and μ come from (``tyre_estimate.TyreData``)
TYRE_SOURCES = ("oracle", "estimated")

_MIN_CAPACITY_N = 1.0e-3
_MAX_MU = 3.0
_MAX_FORCE_N = 1.0e6
_UNMET_REL_TOL = 1.0e-9


_FL, _FR, _RL, _RR = Wheel.FL, Wheel.FR, Wheel.RL, Wheel.RR


@dataclass(frozen=True)
class AllocatorConfig:
    """Allocation method, geometry and limits (SI units)."""

    method: str = param("optimal", "allocation method", choices=METHODS)
    track_width_m: float = param(1.30, "track width B, front = rear",
                                 **field_range("track_width_front_m"))
    wheel_radius_m: float = param(0.27, "effective rolling radius r",
                                  **field_range("wheel_radius_m"))
    motor_torque_max_nm: float = param(500.0, "torque limit of each in-wheel motor, both signs",
                                       **field_range("motor_torque_max_nm"))
    priority: str = param("yaw_moment", "which demand optimal_bounded serves first when both "
                          "cannot be met", choices=PRIORITIES)
    min_fz_n: float = param(100.0, "a wheel with a vertical load at or below this is treated "
                            "as in the air", lo=0.0, hi=1.0e4, unit="N")
    friction_circle: bool = param(True, "optimal_bounded: bound each F_x by the friction "
                                  "circle left over by the current F_y")
    bounded_solver: str = param("osqp", "optimal_bounded: QP solver for the final split",
                                choices=BOUNDED_SOLVERS)
    demand_sanity_factor: float = param(10.0, "demands above this multiple of the motors' "
                                        "capacity are rejected as absurd", lo=1.0, hi=1.0e3)
    brake_balance_front: float = param(0.65, "production: front axle's share of a braking "
                                       "side sum", lo=0.0, hi=1.0)
    tyre_forces: str = param("oracle", "per-wheel F_z, F_y, mu from the state message (oracle: "
                             "the plant's truth, the paper's idealised setting) or estimated "
                             "from the measured a_x, a_y (tyre_estimate)", choices=TYRE_SOURCES)
    mu_nominal: float = param(0.8, "estimated: the road adhesion assumed for every wheel",
                              lo=0.01, hi=3.0)
    # the estimator's vehicle constants: the car file's names and values (unit test)
    mass_kg: float = param(750.0, "estimated: vehicle mass", **field_range("mass_kg"))
    cg_to_front_axle_m: float = param(1.10, "estimated: CG to front axle a",
                                      **field_range("cg_to_front_axle_m"))
    cg_to_rear_axle_m: float = param(1.25, "estimated: CG to rear axle b",
                                     **field_range("cg_to_rear_axle_m"))
    cg_height_m: float = param(0.54, "estimated: CG height h", **field_range("cg_height_m"))
    roll_stiffness_front_share: float = param(0.55, "estimated: front share of the roll "
                                              "stiffness (lateral load transfer split)",
                                              **field_range("roll_stiffness_front_share"))
    gravity_mps2: float = param(9.81, "estimated: gravitational acceleration",
                                **field_range("gravity_mps2"))
    # the wheel-slip limiter after the allocation (core.slip_control): a car's ABS and TCS
    slip_control: bool = param(True, "scale a wheel's torque down once its slip passes "
                               "slip_ratio_on in the torque's direction (ABS, traction control)")
    slip_ratio_on: float = param(0.10, "slip ratio at which the limiter starts", lo=0.01,
                                 hi=1.0)
    slip_ratio_off: float = param(0.25, "slip ratio at which the limiter leaves no torque",
                                  lo=0.02, hi=2.0)
    slip_speed_min_mps: float = param(2.5, "below this speed the limiter is off (standstill), "
                                      "and the slip's denominator floor (the car's)",
                                      **field_range("slip_speed_min_mps"))

    def __post_init__(self) -> None:
        if self.slip_ratio_off <= self.slip_ratio_on:
            raise ValueError(f"slip_ratio_on, slip_ratio_off: the limiter needs on < off, got "
                             f"{self.slip_ratio_on} and {self.slip_ratio_off}")

    @property
    def torque_capacity_nm(self) -> float:
        """Largest |T| the four motors can give (N·m)."""
        return 4.0 * self.motor_torque_max_nm

    @property
    def yaw_moment_capacity_nm(self) -> float:
        """Largest |M_z| the motors can give at T = 0 (N·m): (B/2r)·4·T_max."""
        return 2.0 * self.track_width_m * self.motor_torque_max_nm / self.wheel_radius_m


@dataclass(frozen=True)
class AllocationResult:
    """Wheel torques (N·m, shape (4,), FL FR RL RR, read-only) and the unmet demand."""

    torque_nm: np.ndarray
    unmet_torque_nm: float
    unmet_yaw_moment_nm: float
    status: str


def yaw_moment_nm(torque_nm: np.ndarray, cfg: AllocatorConfig) -> float:
    """Yaw moment (N·m) of wheel torques (4,) by eq. (27): (B/2r)(−T_fl + T_fr − T_rl + T_rr)."""
    t = np.asarray(torque_nm, dtype=float)
    return cfg.track_width_m / (2.0 * cfg.wheel_radius_m) * float(
        -t[_FL] + t[_FR] - t[_RL] + t[_RR])


# ----------------------------------------------------------------------------- helpers


def _vec4(x: object, name: str) -> list[float]:
    a = np.asarray(x, dtype=float)
    if a.shape != (4,):
        raise ValueError(f"allocation: {name} must have shape (4,), got {a.shape}")
    out = a.tolist()
    for v in out:
        if not math.isfinite(v):
            raise ValueError(f"allocation: {name} must be finite, got {out}")
    return out


@dataclass(frozen=True, slots=True)
class _Inputs:
    t: float
    mz: float
    fz: list[float]
    fy: list[float]
    mu: list[float]
    cap: list[float]  # μ_i F_zi of wheels on the ground, 0 for wheels in the air
    lift: bool


def _prepare(t: float, mz: float, fz: object, fy: object, mu: object,
             cfg: AllocatorConfig) -> _Inputs:
    t = float(t)
    mz = float(mz)
    if not math.isfinite(t):
        raise ValueError(f"allocation: total torque T must be finite, got {t!r}")
    if not math.isfinite(mz):
        raise ValueError(f"allocation: yaw moment Mz must be finite, got {mz!r}")
    t_lim = cfg.demand_sanity_factor * cfg.torque_capacity_nm
    if abs(t) > t_lim:
        raise ValueError(f"allocation: total torque T = {t:.6g} N*m exceeds the sanity limit "
                         f"{t_lim:.6g} N*m ({cfg.demand_sanity_factor:g} x capacity)")
    m_lim = cfg.demand_sanity_factor * cfg.yaw_moment_capacity_nm
    if abs(mz) > m_lim:
        raise ValueError(f"allocation: yaw moment Mz = {mz:.6g} N*m exceeds the sanity limit "
                         f"{m_lim:.6g} N*m ({cfg.demand_sanity_factor:g} x capacity)")
    fz_l = _vec4(fz, "fz")
    fy_l = _vec4(fy, "fy")
    mu_l = _vec4(mu, "mu")
    for i in range(4):
        if not 0.0 <= mu_l[i] <= _MAX_MU:
            raise ValueError(f"allocation: mu[{i}] = {mu_l[i]!r} is outside [0, {_MAX_MU}]")
        if abs(fz_l[i]) > _MAX_FORCE_N:
            raise ValueError(f"allocation: fz[{i}] = {fz_l[i]!r} N is absurd")
        if abs(fy_l[i]) > _MAX_FORCE_N:
            raise ValueError(f"allocation: fy[{i}] = {fy_l[i]!r} N is absurd")
    cap = [0.0] * 4
    lift = False
    for i in range(4):
        c = mu_l[i] * fz_l[i]
        if fz_l[i] > cfg.min_fz_n and c > _MIN_CAPACITY_N:
            cap[i] = c
        else:
            lift = True
    return _Inputs(t, mz, fz_l, fy_l, mu_l, cap, lift)


def _side_demands(t: float, mz: float, cfg: AllocatorConfig) -> tuple[float, float]:
    dm = mz * cfg.wheel_radius_m / cfg.track_width_m
    return 0.5 * t - dm, 0.5 * t + dm


def _finish(torques: list[float], inp: _Inputs, cfg: AllocatorConfig,
            extra_flags: tuple[str, ...] = ()) -> AllocationResult:
    tq = np.array(torques, dtype=float)
    tq.setflags(write=False)
    t_ach = torques[0] + torques[1] + torques[2] + torques[3]
    m_ach = cfg.track_width_m / (2.0 * cfg.wheel_radius_m) * (
        -torques[_FL] + torques[_FR] - torques[_RL] + torques[_RR])
    unmet_t = inp.t - t_ach
    unmet_m = inp.mz - m_ach
    flags = []
    if (abs(unmet_t) > _UNMET_REL_TOL * max(1.0, abs(inp.t))
            or abs(unmet_m) > _UNMET_REL_TOL * max(1.0, abs(inp.mz))):
        flags.append("limited")
    if inp.lift:
        flags.append("wheel_lift")
    flags.extend(extra_flags)
    return AllocationResult(tq, unmet_t, unmet_m, ",".join(flags) if flags else "ok")


def _clip_motor(torques: list[float], cfg: AllocatorConfig) -> list[float]:
    lim = cfg.motor_torque_max_nm
    return [_clip(v, -lim, lim) for v in torques]


# ----------------------------------------------------------------------------- methods


def optimal(t_nm: float, mz_nm: float, fz_n: np.ndarray, fy_n: np.ndarray, mu: np.ndarray,
            cfg: AllocatorConfig) -> AllocationResult:
    """Paper's minimum-tyre-load-ratio split, eq. (26)-(31) as corrected (module docstring).

    t_nm: total wheel torque (N·m); mz_nm: yaw moment (N·m, + = left); fz_n, fy_n, mu:
    per-wheel vertical load (N), lateral force (N, unused here) and adhesion, shape (4,).
    Each wheel is finally clipped to ±motor_torque_max_nm.
    """
    inp = _prepare(t_nm, mz_nm, fz_n, fy_n, mu, cfg)
    return _finish(_clip_motor(_optimal_closed_form(inp, cfg), cfg), inp, cfg)


def _optimal_closed_form(inp: _Inputs, cfg: AllocatorConfig) -> list[float]:
    s_left, s_right = _side_demands(inp.t, inp.mz, cfg)
    out = [0.0] * 4
    for front, rear, s in ((_FL, _RL, s_left), (_FR, _RR, s_right)):
        wf = inp.cap[front] * inp.cap[front]
        wr = inp.cap[rear] * inp.cap[rear]
        if wf + wr > 0.0:
            t_rear = s * wr / (wf + wr)  # eq. (31), corrected
            out[rear] = t_rear
            out[front] = s - t_rear  # eq. (28), corrected
    return out


def rule(t_nm: float, mz_nm: float, fz_n: np.ndarray, fy_n: np.ndarray, mu: np.ndarray,
         cfg: AllocatorConfig) -> AllocationResult:
    """Conventional baseline: equal front/rear split of each side sum T/2 ∓ M_z r/B, clipped
    to the motor limits. Arguments as :func:`optimal` (loads are checked but not used)."""
    inp = _prepare(t_nm, mz_nm, fz_n, fy_n, mu, cfg)
    s_left, s_right = _side_demands(inp.t, inp.mz, cfg)
    raw = [0.5 * s_left, 0.5 * s_right, 0.5 * s_left, 0.5 * s_right]
    return _finish(_clip_motor(raw, cfg), inp, cfg)


def production(t_nm: float, mz_nm: float, fz_n: np.ndarray, fy_n: np.ndarray,
               mu: np.ndarray, cfg: AllocatorConfig) -> AllocationResult:
    """The fair baseline: each side sum split front/rear by static axle load when it drives
    and by the brake balance when it brakes (module docstring), clipped to the motor limits.
    Arguments as :func:`optimal` (loads are checked but not used)."""
    inp = _prepare(t_nm, mz_nm, fz_n, fy_n, mu, cfg)
    drive_front = cfg.cg_to_rear_axle_m / (cfg.cg_to_front_axle_m + cfg.cg_to_rear_axle_m)
    out = [0.0] * 4
    for front, rear, s in zip((_FL, _FR), (_RL, _RR), _side_demands(inp.t, inp.mz, cfg),
                              strict=True):
        share = drive_front if s >= 0.0 else cfg.brake_balance_front
        out[front], out[rear] = share * s, (1.0 - share) * s
    return _finish(_clip_motor(out, cfg), inp, cfg)


def equal(t_nm: float, mz_nm: float, fz_n: np.ndarray, fy_n: np.ndarray, mu: np.ndarray,
          cfg: AllocatorConfig) -> AllocationResult:
    """T/4 per wheel, clipped to the motor limits; M_z is not served (reported unmet)."""
    inp = _prepare(t_nm, mz_nm, fz_n, fy_n, mu, cfg)
    q = 0.25 * inp.t
    return _finish(_clip_motor([q, q, q, q], cfg), inp, cfg)


def wheel_bounds_nm(fz_n: np.ndarray, fy_n: np.ndarray, mu: np.ndarray,
                    cfg: AllocatorConfig) -> np.ndarray:
    """Per-wheel torque bounds b_i (N·m, shape (4,)) used by :func:`optimal_bounded`:
    |T_i| ≤ min(T_motor,max, r √max((μ_i F_zi)² − F_yi², 0)); 0 for a wheel in the air."""
    inp = _prepare(0.0, 0.0, fz_n, fy_n, mu, cfg)
    return np.array(_bounds(inp, cfg))


def _bounds(inp: _Inputs, cfg: AllocatorConfig) -> list[float]:
    lim = cfg.motor_torque_max_nm
    r = cfg.wheel_radius_m
    out = [0.0] * 4
    for i in range(4):
        c = inp.cap[i]
        if c <= 0.0:
            continue
        if cfg.friction_circle:
            fx_max = math.sqrt(max(c * c - inp.fy[i] * inp.fy[i], 0.0))
            out[i] = min(lim, r * fx_max)
        else:
            out[i] = lim
    return out


def _achievable_sides(s_left: float, s_right: float, bl: float, br: float,
                      priority: str) -> tuple[float, float]:
    """Lexicographic projection of the side-sum demand onto |S_L| ≤ bl, |S_R| ≤ br."""
    if -bl <= s_left <= bl and -br <= s_right <= br:
        return s_left, s_right
    if priority == "yaw_moment":
        d = _clip(s_right - s_left, -(bl + br), bl + br)
        lo = max(-bl, -br - d)
        hi = min(bl, br - d)
        sl = _clip(0.5 * ((s_left + s_right) - d), lo, hi)
        return sl, sl + d
    tot = _clip(s_left + s_right, -(bl + br), bl + br)
    lo = max(-bl, tot - br)
    hi = min(bl, tot + br)
    sl = _clip(0.5 * (tot - (s_right - s_left)), lo, hi)
    return sl, tot - sl


def _split_side(s: float, wf: float, wr: float, bf: float, br: float) -> tuple[float, float]:
    """min x_f²/w_f + x_r²/w_r s.t. x_f + x_r = s, |x_f| ≤ bf, |x_r| ≤ br (|s| ≤ bf + br)."""
    if wf + wr <= 0.0:
        return 0.0, 0.0
    xr = s * wr / (wf + wr)
    xf = s - xr
    if abs(xr) > br:
        xr = math.copysign(br, s)
        xf = s - xr
    elif abs(xf) > bf:
        xf = math.copysign(bf, s)
        xr = s - xf
    return _clip(xf, -bf, bf), _clip(xr, -br, br)


_DEFAULT_QP: BoundedQp | None = None


def _default_qp() -> BoundedQp:
    global _DEFAULT_QP
    if _DEFAULT_QP is None:
        _DEFAULT_QP = BoundedQp()
    return _DEFAULT_QP


def optimal_bounded(t_nm: float, mz_nm: float, fz_n: np.ndarray, fy_n: np.ndarray,
                    mu: np.ndarray, cfg: AllocatorConfig,
                    qp: BoundedQp | None = None) -> AllocationResult:
    """Minimum tyre-load-ratio split with motor and friction-circle bounds and a priority.

    Arguments as :func:`optimal`; fy_n is used for the friction circle. ``qp`` is the OSQP
    workspace for ``bounded_solver = "osqp"`` (a process-wide one is created when None).
    """
    inp = _prepare(t_nm, mz_nm, fz_n, fy_n, mu, cfg)
    b = _bounds(inp, cfg)
    s_left, s_right = _side_demands(inp.t, inp.mz, cfg)
    sl, sr = _achievable_sides(s_left, s_right, b[_FL] + b[_RL], b[_FR] + b[_RR],
                               cfg.priority)
    cap = inp.cap
    flags: tuple[str, ...] = ()
    torques: list[float] | None = None
    if cfg.bounded_solver == "osqp" and any(v > 0.0 for v in b):
        solver = qp if qp is not None else _default_qp()
        torques = solver.solve(sl, sr, cap, b, cfg.motor_torque_max_nm)
        if torques is None:
            flags = ("solver_fallback",)
    if torques is None:
        xfl, xrl = _split_side(sl, cap[_FL] ** 2, cap[_RL] ** 2, b[_FL], b[_RL])
        xfr, xrr = _split_side(sr, cap[_FR] ** 2, cap[_RR] ** 2, b[_FR], b[_RR])
        torques = [xfl, xfr, xrl, xrr]
    return _finish(torques, inp, cfg, flags)


_METHODS = {"optimal": optimal, "rule": rule, "equal": equal, "production": production}


def allocate(method: str, t_nm: float, mz_nm: float, fz_n: np.ndarray, fy_n: np.ndarray,
             mu: np.ndarray, cfg: AllocatorConfig,
             qp: BoundedQp | None = None) -> AllocationResult:
    """Dispatch to one of :data:`METHODS`; raises ``ValueError`` on an unknown method or a
    bad input (see the module docstring)."""
    if method == "optimal_bounded":
        return optimal_bounded(t_nm, mz_nm, fz_n, fy_n, mu, cfg, qp)
    fn = _METHODS.get(method)
    if fn is None:
        raise ValueError(f"allocation: method '{method}' is not one of {list(METHODS)}")
    return fn(t_nm, mz_nm, fz_n, fy_n, mu, cfg)


class TorqueAllocator:
    """Stateful convenience for a node: a config plus its own OSQP workspace."""

    def __init__(self, cfg: AllocatorConfig | None = None) -> None:
        self.cfg = cfg if cfg is not None else AllocatorConfig()
        self._qp = (BoundedQp() if self.cfg.method == "optimal_bounded"
                    and self.cfg.bounded_solver == "osqp" else None)

    def allocate(self, t_nm: float, mz_nm: float, fz_n: np.ndarray, fy_n: np.ndarray,
                 mu: np.ndarray, motion: WheelMotion | None = None) -> AllocationResult:
        """Allocate with ``cfg.method`` (:func:`allocate`), then, given the wheels'
        ``motion`` and ``cfg.slip_control``, limit each wheel's slip
        (:func:`~fourws_torque_alloc.core.slip_control.limit_slip`); the unmet demand is
        what the limited torques leave, the status gains ``slip_limited``."""
        res = allocate(self.cfg.method, t_nm, mz_nm, fz_n, fy_n, mu, self.cfg, self._qp)
        if motion is None or not self.cfg.slip_control:
            return res
        cfg = self.cfg
        tq, limited = limit_slip(res.torque_nm, motion, a_m=cfg.cg_to_front_axle_m,
                                 b_m=cfg.cg_to_rear_axle_m, track_m=cfg.track_width_m,
                                 radius_m=cfg.wheel_radius_m, kappa_on=cfg.slip_ratio_on,
                                 kappa_off=cfg.slip_ratio_off,
                                 v_min_mps=cfg.slip_speed_min_mps)
        if not limited.any():
            return res
        tq.setflags(write=False)
        removed = res.torque_nm - tq
        status = "slip_limited" if res.status == "ok" else res.status + ",slip_limited"
        return AllocationResult(tq, res.unmet_torque_nm + float(removed.sum()),
                                res.unmet_yaw_moment_nm + yaw_moment_nm(removed, cfg), status)
