"""Steps the plant (vehicle model, road, actuators) with fixed-step RK4.

``Simulator.step`` holds the commands (δf, δr, four wheel torques) constant for ``dt_s``
(zero-order hold, as a 100 Hz controller does) and integrates the 26-state model of
``vehicle.py`` with classical RK4 at ``substep_s`` (default 1 ms; ``dt_s`` must be an integer
multiple; from 2.5 ms up the wheel-spin mode goes unstable at low speed, see ``vehicle.py``);
docs/plant.md, "Simulator". Commands outside the actuator limits are clipped (``last_clipped``
names the channels, for the node to warn); non-finite commands raise ``ValueError``. The road
μ under each wheel is sampled at the start of each substep.

The integration runs compiled (numba, ``rk4.py`` on ``model_jit.py``): the equations and the
order of operations of the plain-float :meth:`TwoTrackModel.derivatives
<fourws_sim.core.vehicle.TwoTrackModel.derivatives>` and of the plain-Python RK4 loop, which
``jit=False`` still runs (the reference the tests compare the compiled path with). On a
uniform road one compiled call integrates a whole control period (with a steering dead time:
each run of substeps with the same delayed command); a μ that changes between substeps
(``road.uniform`` False) is looked up in Python before each substep. A fixed order of
operations throughout, so two runs with the same inputs give bit-identical outputs. Time is
the integer count of substeps times the substep, rounded to 1e-12 s, so the 10 ms grid has no
accumulated drift.

Initial state: the scenario's position, heading and speed, v_y = r = 0, wheels rolling
freely (ω = v/R), actuators at rest (zero torque, zero steer), no load transfer, transient
slip angles at their steady values. The initial state and the outputs are
:class:`~fourws_sim.core.plant_io.InitialState` and
:class:`~fourws_sim.core.plant_io.PlantOutputs` (``plant_io.py``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from fourws_sim.core import rk4
from fourws_sim.core.actuators import check_finite_commands, clip_commands
from fourws_sim.core.model_jit import model_constants
from fourws_sim.core.plant_io import InitialState, PlantOutputs
from fourws_sim.core.rk4 import AUX_ALPHA, AUX_AX, AUX_AY, AUX_FX, AUX_FY, AUX_FZ
from fourws_sim.core.road import Road
from fourws_sim.core.sensing import DeadTime
from fourws_sim.core.vehicle import ALPHA, N_STATE, OMEGA, TORQUE, State, TwoTrackModel
from fourws_sim.core.vehicle_params import VehicleParams

if TYPE_CHECKING:
    from fourws_sim.core.scenario import Scenario

# (v_x, v_y, r, X, Y, ψ) and (δ_f, δ_r) in the state list: plain-int slices (an enum
# member's lookup costs more than the rest of the per-step bookkeeping)
_BODY = slice(int(State.VX), int(State.YAW) + 1)
_POSE = slice(int(State.X), int(State.YAW) + 1)
_STEER = slice(int(State.STEER_FRONT), int(State.STEER_REAR) + 1)


#: the longest steering dead time the plant takes, s
MAX_STEER_DEAD_TIME_S = 1.0


class Simulator:
    """Fixed-step RK4 plant. See the module docstring.

    ``jit=False`` integrates with the plain-Python reference (``TwoTrackModel.derivatives``
    and the RK4 loop in Python floats) instead of the compiled code; same results up to the
    last bits of the transcendental functions.
    """

    def __init__(
        self,
        vehicle: VehicleParams,
        road: Road,
        initial: InitialState,
        substep_s: float = 0.001,
        steer_dead_time_s: float = 0.0,
        *,
        jit: bool = True,
    ) -> None:
        if not (math.isfinite(substep_s) and 1e-5 <= substep_s <= 0.01):
            raise ValueError(f"substep_s: {substep_s} is outside [1e-05, 0.01] s")
        if not (math.isfinite(steer_dead_time_s)
                and 0.0 <= steer_dead_time_s <= MAX_STEER_DEAD_TIME_S):
            raise ValueError(f"steer_dead_time_s: {steer_dead_time_s} is outside "
                             f"[0, {MAX_STEER_DEAD_TIME_S:g}] s")
        n_dead = round(steer_dead_time_s / substep_s)
        if abs(n_dead * substep_s - steer_dead_time_s) > 1e-9:
            raise ValueError(f"steer_dead_time_s: {steer_dead_time_s} s is not a multiple of "
                             f"substep_s = {substep_s} s")
        #: a pure dead time of the steering commands before the actuators (None: none)
        self._dead = DeadTime(n_dead, (0.0, 0.0)) if n_dead else None
        self.vehicle = vehicle
        self.road = road
        self.initial = initial
        self.substep_s = float(substep_s)
        self._jit = bool(jit)
        self._model = TwoTrackModel(vehicle)
        self._c = model_constants(self._model)
        self._limits = vehicle.actuator_limits()
        self._xw, self._yw = vehicle.wheel_positions_m()
        self._n_sub = 0
        # the last μ tuple and its array (a uniform road returns the same tuple every time)
        self._mu_key: tuple[float, ...] = ()
        self._mu_arr = np.zeros(4)
        y = np.zeros(N_STATE)
        y[State.VX] = initial.speed
        y[State.VY] = initial.vy
        y[State.R] = initial.yaw_rate
        y[State.X] = initial.x
        y[State.Y] = initial.y
        y[State.YAW] = initial.yaw
        y[OMEGA] = initial.speed / vehicle.wheel_radius_m
        self._u: tuple[float, ...] = (0.0,) * 6
        self._u_arr = np.zeros(6)
        y[ALPHA] = self._evaluate(y, self._mu(initial.x, initial.y, initial.yaw))[
            AUX_ALPHA:AUX_ALPHA + 4]
        #: the state, float64 (N_STATE,) in State order
        self._y = y
        self.last_clipped: tuple[str, ...] = ()
        """Names of the command channels clipped in the last :meth:`step`."""

    @classmethod
    def from_scenario(cls, scenario: Scenario, substep_s: float = 0.001,
                      steer_dead_time_s: float = 0.0) -> Simulator:
        """A simulator at the scenario's initial state, vehicle and road."""
        return cls(scenario.vehicle, scenario.road, scenario.initial, substep_s,
                   steer_dead_time_s)

    def warm_up(self, dt_s: float = 0.01) -> None:
        """Integrate one period of a throwaway twin at rest: it loads the compiled kernels
        from numba's disk cache (docs/architecture.md, "Compiled numerics"), so that a node's
        first step takes its usual time. This simulator does not change."""
        twin = Simulator(self.vehicle, self.road, self.initial, self.substep_s,
                         self._dead.substeps * self.substep_s if self._dead is not None else 0.0)
        twin.advance(0.0, 0.0, np.zeros(4), dt_s)

    @property
    def t_s(self) -> float:
        """Simulated time, s."""
        return round(self._n_sub * self.substep_s, 12)

    def state(self) -> np.ndarray:
        """Copy of the state vector, indexed by :class:`~fourws_sim.core.vehicle.State`."""
        return self._y.copy()

    def _mu(self, px: float, py: float, yaw: float) -> tuple[float, float, float, float]:
        """μ under the four wheels with the CG at (px, py) and heading ``yaw``."""
        road = self.road
        if road.uniform:
            return road.mu4((), ())
        c, s = math.cos(yaw), math.sin(yaw)
        (x0, x1, x2, x3), (y0, y1, y2, y3) = self._xw, self._yw
        return road.mu4(
            (px + x0 * c - y0 * s, px + x1 * c - y1 * s, px + x2 * c - y2 * s,
             px + x3 * c - y3 * s),
            (py + x0 * s + y0 * c, py + x1 * s + y1 * c, py + x2 * s + y2 * c,
             py + x3 * s + y3 * c),
        )

    def _mu_array(self, mu: tuple[float, ...]) -> np.ndarray:
        """``mu`` as a float64 array (cached while it does not change; never mutate it)."""
        if mu != self._mu_key:
            self._mu_arr = np.array(mu, dtype=np.float64)
            self._mu_key = mu
        return self._mu_arr

    def _evaluate(self, y: np.ndarray, mu: tuple[float, ...]) -> np.ndarray:
        """The model at state ``y`` with the held command and road ``mu``: a_x, a_y, F_x,
        F_y, F_z and the kinematic α in one array (layout ``rk4.AUX_*``)."""
        if self._jit:
            return rk4.outputs(y, self._u_arr, self._mu_array(mu), self._c)
        info: dict[str, Any] = {}
        self._model.derivatives(y.tolist(), self._u, mu, info)
        return np.array((info["ax"], info["ay"], *info["fx"], *info["fy"], *info["fz"],
                         *info["alpha"]), dtype=np.float64)

    def outputs(self) -> PlantOutputs:
        """The plant outputs at the current time."""
        y = self._y
        v = y.tolist()
        vx, vy, r, px, py, yaw = v[_BODY]
        steer_front, steer_rear = v[_STEER]
        mu = self._mu(px, py, yaw)
        aux = self._evaluate(y, mu)
        return PlantOutputs(
            t_s=self.t_s,
            x=px,
            y=py,
            yaw=yaw,
            vx=vx,
            vy=vy,
            yaw_rate=r,
            ax=float(aux[AUX_AX]),
            ay=float(aux[AUX_AY]),
            sideslip=math.atan2(vy, vx),
            steer_front=steer_front,
            steer_rear=steer_rear,
            wheel_speed=y[OMEGA].copy(),
            wheel_torque=y[TORQUE].copy(),
            fx=aux[AUX_FX:AUX_FX + 4],
            fy=aux[AUX_FY:AUX_FY + 4],
            fz=aux[AUX_FZ:AUX_FZ + 4],
            mu=np.array(mu, dtype=float),
        )

    def step(
        self,
        steer_front_cmd: float,
        steer_rear_cmd: float,
        wheel_torque_cmd: np.ndarray,
        dt_s: float = 0.01,
    ) -> PlantOutputs:
        """Hold the commands for ``dt_s``, integrate with fixed-step RK4 at ``substep_s``
        (``dt_s`` must be an integer multiple), return the outputs at t + dt.

        Steer commands in rad (road-wheel angles), wheel torques (4,) in N·m FL FR RL RR.
        """
        self.advance(steer_front_cmd, steer_rear_cmd, wheel_torque_cmd, dt_s)
        return self.outputs()

    def advance(
        self,
        steer_front_cmd: float,
        steer_rear_cmd: float,
        wheel_torque_cmd: np.ndarray,
        dt_s: float = 0.01,
    ) -> None:
        """:meth:`step` without building the outputs."""
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise ValueError(f"dt_s: must be a positive finite number, got {dt_s!r}")
        h = self.substep_s
        n = round(dt_s / h)
        if n < 1 or abs(n * h - dt_s) > 1e-9 * max(dt_s, 1e-3):
            raise ValueError(f"dt_s: {dt_s} s is not an integer multiple of substep_s = {h} s")
        sf, sr, torques = check_finite_commands(steer_front_cmd, steer_rear_cmd, wheel_torque_cmd)
        u, self.last_clipped = clip_commands(sf, sr, torques, self._limits)
        self._u = u
        if not self._jit:
            self._advance_python(n, sf, sr, torques)
            return
        y, c, road = self._y, self._c, self.road
        dead = self._dead
        if dead is None:
            runs: list[tuple[int, tuple[float, ...], tuple[str, ...]]] = [
                (n, u, self.last_clipped)]
        else:
            dead.command(self._n_sub, (sf, sr))
            runs = self._dead_time_runs(dead, n, torques)
        for count, u_run, clipped in runs:
            self._u, self.last_clipped = u_run, clipped
            u_arr = self._u_arr = np.array(u_run, dtype=np.float64)
            if road.uniform:
                rk4.integrate(y, u_arr, self._mu_array(road.mu4((), ())), c, h, count)
                continue
            for _ in range(count):
                # μ at the start of each substep, from the wheels' contact points
                px, py, yaw = y[_POSE].tolist()
                rk4.integrate(y, u_arr, self._mu_array(self._mu(px, py, yaw)), c, h, 1)
        self._n_sub += n

    def _dead_time_runs(
        self, dead: DeadTime, n: int, torques: tuple[float, float, float, float]
    ) -> list[tuple[int, tuple[float, ...], tuple[str, ...]]]:
        """The next ``n`` substeps as runs of (substeps, clipped command, clipped channels)
        with one command each: the command of each substep is the one issued a dead time
        before it."""
        runs: list[tuple[int, tuple[float, ...], tuple[str, ...]]] = []
        i0 = self._n_sub
        cmd = dead.at(i0)
        count = 1
        for i in range(i0 + 1, i0 + n):
            nxt = dead.at(i)
            if nxt == cmd:
                count += 1
                continue
            runs.append((count, *clip_commands(*cmd, torques, self._limits)))
            cmd, count = nxt, 1
        runs.append((count, *clip_commands(*cmd, torques, self._limits)))
        return runs

    def _advance_python(
        self, n: int, sf: float, sr: float, torques: tuple[float, float, float, float]
    ) -> None:
        """The plain-Python RK4 loop (``jit=False``): the reference of the compiled path."""
        u = self._u
        f = self._model.derivatives
        h = self.substep_s
        hh, h6 = 0.5 * h, h / 6.0
        y = self._y.tolist()
        uniform = self.road.uniform
        mu = self.road.mu4((), ()) if uniform else None
        dead = self._dead
        if dead is not None:
            dead.command(self._n_sub, (sf, sr))
        for i in range(n):
            if dead is not None:
                # the command of each substep is the one issued a dead time before it
                u, self.last_clipped = clip_commands(*dead.at(self._n_sub + i), torques,
                                                     self._limits)
                self._u = u
            if not uniform:
                mu = self._mu(y[State.X], y[State.Y], y[State.YAW])
            k1 = f(y, u, mu)
            k2 = f([a + hh * b for a, b in zip(y, k1, strict=True)], u, mu)
            k3 = f([a + hh * b for a, b in zip(y, k2, strict=True)], u, mu)
            k4 = f([a + h * b for a, b in zip(y, k3, strict=True)], u, mu)
            y = [
                a + h6 * (b1 + 2.0 * (b2 + b3) + b4)
                for a, b1, b2, b3, b4 in zip(y, k1, k2, k3, k4, strict=True)
            ]
        self._y = np.array(y, dtype=np.float64)
        self._u_arr = np.array(u, dtype=np.float64)
        self._n_sub += n
