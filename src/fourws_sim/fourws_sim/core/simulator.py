"""The plant: vehicle model + road + actuators, stepped with fixed-step RK4.

``Simulator.step`` holds the commands (δf, δr, four wheel torques) constant for ``dt_s``
(zero-order hold, as a 100 Hz controller does) and integrates the 26-state model of
``vehicle.py`` with classical RK4 at ``substep_s`` (default 1 ms; ``dt_s`` must be an integer
multiple; from 2.5 ms up the wheel-spin mode goes unstable at low speed, see ``vehicle.py``).
Commands outside the actuator limits are clipped (``last_clipped`` names the
channels, for the node to warn); non-finite commands raise ``ValueError``. The road μ under
each wheel is sampled at the start of each substep.

Everything is plain Python floats in a fixed order of operations, so two runs with the same
inputs give bit-identical outputs. Time is the integer count of substeps times the substep,
rounded to 1e-12 s, so the 10 ms grid has no accumulated drift.

Initial state: the scenario's position, heading and speed, v_y = r = 0, wheels rolling
freely (ω = v/R), actuators at rest (zero torque, zero steer), no load transfer, transient
slip angles at their steady values.

The initial state and the outputs are :class:`~fourws_sim.core.plant_io.InitialState` and
:class:`~fourws_sim.core.plant_io.PlantOutputs` (``plant_io.py``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from fourws_sim.core.actuators import check_finite_commands, clip_commands
from fourws_sim.core.plant_io import InitialState, PlantOutputs
from fourws_sim.core.road import Road
from fourws_sim.core.sensing import DeadTime
from fourws_sim.core.vehicle import ALPHA, N_STATE, State, TwoTrackModel
from fourws_sim.core.vehicle_params import VehicleParams

if TYPE_CHECKING:
    from fourws_sim.core.scenario import Scenario


class Simulator:
    """Fixed-step RK4 plant. See the module docstring."""

    def __init__(
        self,
        vehicle: VehicleParams,
        road: Road,
        initial: InitialState,
        substep_s: float = 0.001,
        steer_dead_time_s: float = 0.0,
    ) -> None:
        if not (math.isfinite(substep_s) and 1e-5 <= substep_s <= 0.01):
            raise ValueError(f"substep_s: {substep_s} is outside [1e-05, 0.01] s")
        if not (math.isfinite(steer_dead_time_s) and 0.0 <= steer_dead_time_s <= 1.0):
            raise ValueError(f"steer_dead_time_s: {steer_dead_time_s} is outside [0, 1] s")
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
        self._model = TwoTrackModel(vehicle)
        self._limits = vehicle.actuator_limits()
        self._xw, self._yw = vehicle.wheel_positions_m()
        self._n_sub = 0
        y = [0.0] * N_STATE
        y[State.VX] = initial.speed
        y[State.VY] = initial.vy
        y[State.R] = initial.yaw_rate
        y[State.X] = initial.x
        y[State.Y] = initial.y
        y[State.YAW] = initial.yaw
        omega = initial.speed / vehicle.wheel_radius_m
        for i in range(4):
            y[State.OMEGA_FL + i] = omega
        self._u: tuple[float, ...] = (0.0,) * 6
        info: dict[str, Any] = {}
        self._model.derivatives(y, self._u, self._mu(y), info)
        y[ALPHA] = info["alpha"]
        self._y = y
        self.last_clipped: tuple[str, ...] = ()
        """Names of the command channels clipped in the last :meth:`step`."""

    @classmethod
    def from_scenario(cls, scenario: Scenario, substep_s: float = 0.001,
                      steer_dead_time_s: float = 0.0) -> Simulator:
        """A simulator at the scenario's initial state, vehicle and road."""
        return cls(scenario.vehicle, scenario.road, scenario.initial, substep_s,
                   steer_dead_time_s)

    @property
    def t_s(self) -> float:
        """Simulated time, s."""
        return round(self._n_sub * self.substep_s, 12)

    def state(self) -> np.ndarray:
        """Copy of the state vector, indexed by :class:`~fourws_sim.core.vehicle.State`."""
        return np.array(self._y)

    def _mu(self, y: list[float]) -> tuple[float, float, float, float]:
        road = self.road
        if road.uniform:
            return road.mu4((), ())
        px, py, yaw = y[State.X], y[State.Y], y[State.YAW]
        c, s = math.cos(yaw), math.sin(yaw)
        (x0, x1, x2, x3), (y0, y1, y2, y3) = self._xw, self._yw
        return road.mu4(
            (px + x0 * c - y0 * s, px + x1 * c - y1 * s, px + x2 * c - y2 * s,
             px + x3 * c - y3 * s),
            (py + x0 * s + y0 * c, py + x1 * s + y1 * c, py + x2 * s + y2 * c,
             py + x3 * s + y3 * c),
        )

    def outputs(self) -> PlantOutputs:
        """The plant outputs at the current time."""
        y = self._y
        mu = self._mu(y)
        info: dict[str, Any] = {}
        self._model.derivatives(y, self._u, mu, info)
        vx, vy = y[State.VX], y[State.VY]
        return PlantOutputs(
            t_s=self.t_s,
            x=y[State.X],
            y=y[State.Y],
            yaw=y[State.YAW],
            vx=vx,
            vy=vy,
            yaw_rate=y[State.R],
            ax=info["ax"],
            ay=info["ay"],
            sideslip=math.atan2(vy, vx),
            steer_front=y[State.STEER_FRONT],
            steer_rear=y[State.STEER_REAR],
            wheel_speed=np.array(y[State.OMEGA_FL:State.OMEGA_RR + 1]),
            wheel_torque=np.array(y[State.TORQUE_FL:State.TORQUE_RR + 1]),
            fx=np.array(info["fx"]),
            fy=np.array(info["fy"]),
            fz=np.array(info["fz"]),
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
        f = self._model.derivatives
        hh, h6 = 0.5 * h, h / 6.0
        y = self._y
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
                mu = self._mu(y)
            k1 = f(y, u, mu)
            k2 = f([a + hh * b for a, b in zip(y, k1, strict=True)], u, mu)
            k3 = f([a + hh * b for a, b in zip(y, k2, strict=True)], u, mu)
            k4 = f([a + h * b for a, b in zip(y, k3, strict=True)], u, mu)
            y = [
                a + h6 * (b1 + 2.0 * (b2 + b3) + b4)
                for a, b1, b2, b3, b4 in zip(y, k1, k2, k3, k4, strict=True)
            ]
        self._y = y
        self._n_sub += n
