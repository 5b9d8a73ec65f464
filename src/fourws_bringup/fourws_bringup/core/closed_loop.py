"""The whole control loop in one process, without ROS: plant, MPC, speed PID, allocator.

Same sequencing as the lockstep graph (docs/graph.md, "Timing") at every step k::

    outputs(k) ──► mpc.step(t_k, outputs(k), mu=mean μ)      → δf, δr, Mz      (mpc_node)
               ──► pid.step(v_ref, vx, T, a_ref)             → T_total         (speed_pid_node)
               ──► allocate(method, T_total, Mz, fz, fy, μ)  → 4 wheel torques (allocator_node)
               ──► mpc.report_delivered(Mz − unmet Mz)       (mpc_node, from wheel_torques)
               ──► plant.step(δf, δr, torques, T)            → outputs(k+1)    (plant_node)

until the scenario ends (its ``check_end``: end X, duration, end of path, or an abort) or
``max_steps``. As in speed_pid_node, v_ref is the reference speed at the path sample nearest
to the car and a_ref = v dv/ds there (``fourws_common.path_lookup.SpeedProfile``).
Configuration comes from the same YAML files as the nodes, merged in the same order
(``fourws_bringup.core.configs``): ``fourws_mpc/config/mpc.yaml`` with the controller preset
``fourws_bringup/config/controllers/<name>.yaml`` over it (``mpc_node`` and ``allocator_node``
sections), ``fourws_torque_alloc/config/{speed_pid,allocator}.yaml`` and
``fourws_sim/config/plant.yaml`` (period and RK4 substep).

The core reads no clock. Pass ``clock`` (e.g. ``time.perf_counter``) to record the wall time
of each ``mpc.step`` call in ``solve_ms`` (NaN otherwise). :func:`run_closed_loop` returns a
:class:`ClosedLoopLog` (docs/mpc.md, "Public API").
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fourws_bringup.core.conditions import IDEAL, Condition, node_parameters
from fourws_bringup.core.configs import (
    load_allocator_config,
    load_mpc_config,
    load_pid_config,
    plant_values,
)
from fourws_bringup.core.metrics import path_nearest, run_metrics
from fourws_common.input_guard import state_mu
from fourws_common.path_lookup import SpeedProfile
from fourws_mpc.core.controller import VehicleSample
from fourws_mpc.core.laws import make_controller
from fourws_mpc.core.reference import Reference
from fourws_sim.core.paths import VEHICLE_WIDTH_M
from fourws_sim.core.scenario import AbortLimits, load_scenario
from fourws_sim.core.sensing import sensors_from_params
from fourws_sim.core.simulator import Simulator
from fourws_torque_alloc.core.allocation import TorqueAllocator
from fourws_torque_alloc.core.pid import SpeedPid
from fourws_torque_alloc.core.slip_control import WheelMotion
from fourws_torque_alloc.core.tyre_estimate import TyreData

STATE_FIELDS = ("t_s", "x", "y", "yaw", "vx", "vy", "yaw_rate", "ax", "ay", "sideslip",
                "steer_front", "steer_rear")
WHEEL_FIELDS = ("wheel_speed", "wheel_torque", "fx", "fy", "fz", "mu")
MPC_FIELDS = ("delta_front", "delta_rear", "yaw_moment", "np", "nc", "q_y", "q_phi",
              "r_ddelta", "r_dmz", "lateral_error", "heading_error", "e_s", "k_e", "k_u",
              "iterations", "slack", "fallback", "mu_estimate", "yaw_moment_bound")


@dataclass
class ClosedLoopLog:
    """Per-step arrays of a closed-loop run (SI). ``state`` holds every VehicleState field,
    ``mpc`` the command and diagnostics, plus the drive demand and the wheel torque commands."""

    scenario: str
    controller: str
    allocation: str
    reference: Reference
    state: dict[str, np.ndarray] = field(default_factory=dict)
    mpc: dict[str, np.ndarray] = field(default_factory=dict)
    solver_status: list[str] = field(default_factory=list)
    drive_force_n: np.ndarray = field(default_factory=lambda: np.zeros(0))
    drive_torque_nm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    wheel_torque_cmd_nm: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    solve_ms: np.ndarray = field(default_factory=lambda: np.zeros(0))
    completed: bool = False
    reason: str = ""
    summary: str = ""
    #: the scenario path's cone lanes (``ReferencePath.lanes``), for the limit metrics
    lanes: tuple = ()
    #: the body width the lanes are checked against (``ReferencePath.vehicle_width_m``)
    vehicle_width_m: float = VEHICLE_WIDTH_M

    @property
    def steps(self) -> int:
        """Number of control steps taken."""
        return len(self.drive_force_n)

    @functools.cached_property
    def nearest(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(e_Y, e_φ, nearest index) of the true poses (``metrics.path_nearest``), computed
        once for :meth:`metrics` and the limit metrics."""
        s = self.state
        return path_nearest(self.reference, s["x"], s["y"], s["yaw"])

    def metrics(self) -> dict[str, Any]:
        """metrics.json values of this run (errors recomputed from the poses)."""
        s = self.state
        m: dict[str, Any] = {"scenario": self.scenario, "controller": self.controller}
        m.update(run_metrics(self.reference, s["t_s"], s["x"], s["y"], s["yaw"], s["vx"],
                             s["vy"], s["sideslip"], self.solve_ms, errors=self.nearest[:2]))
        m["completed"] = self.completed
        m["reason"] = self.reason
        return m


def run_closed_loop(
    scenario_name_or_path: str,
    controller_name: str,
    max_steps: int | None = None,
    *,
    mpc_overrides: dict[str, Any] | None = None,
    clock: Callable[[], float] | None = None,
    condition: Condition = IDEAL,
) -> ClosedLoopLog:
    """Run one scenario with one controller preset; see the module docstring.

    ``mpc_overrides`` replaces MPC parameters after the preset (for studies and tests);
    ``condition`` (``core.conditions``) sets what the controllers see and how late their
    commands act. The log's state is always the plant's truth, so every metric is computed
    on the truth.
    """
    params = node_parameters(condition)
    plant = {**plant_values(), **params["plant_node"]}
    scenario = load_scenario(scenario_name_or_path, vehicle=plant.get("vehicle_file") or None
                             ).with_vehicle_overrides(plant.get("vehicle_overrides", ""))
    abort = AbortLimits.of(plant["abort_lateral_error_m"], plant["abort_sideslip_deg"])
    mpc_cfg = load_mpc_config(controller_name, {**params["mpc_node"],
                                                **(mpc_overrides or {})})
    alloc_cfg = load_allocator_config(controller_name, params["allocator_node"])
    dt, substep = float(plant.get("dt_s", 0.01)), float(plant.get("substep_s", 0.001))
    if abs(dt - mpc_cfg.dt_s) > 1e-12:
        raise ValueError(f"dt_s: plant period {dt} s differs from the MPC's {mpc_cfg.dt_s} s")
    sim = Simulator.from_scenario(scenario, substep_s=substep,
                                  steer_dead_time_s=float(plant.get("steer_dead_time_s", 0.0)))
    sensors = sensors_from_params(plant, dt, initial_command=(0.0, 0.0, np.zeros(4)))
    tyre_data = TyreData(alloc_cfg)
    mpc = make_controller(mpc_cfg)
    pid = SpeedPid(load_pid_config(params["speed_pid_node"]))
    alloc = TorqueAllocator(alloc_cfg)
    p = scenario.path
    ref = mpc_cfg.reference(p.x, p.y, p.yaw, p.curvature, p.speed)
    speed_ref = SpeedProfile(scenario.path.x, scenario.path.y, scenario.path.speed)

    st: dict[str, list] = {k: [] for k in STATE_FIELDS + WHEEL_FIELDS}
    mp: dict[str, list] = {k: [] for k in MPC_FIELDS}
    status: list[str] = []
    force, torque, wcmd, solve = [], [], [], []
    out = sim.outputs()
    done, reason = scenario.check_end(out, abort)
    k = 0
    while not done and (max_steps is None or k < max_steps):
        seen = sensors.measure(out)
        fz, fy, mu = tyre_data.of(seen)
        t0 = clock() if clock is not None else 0.0
        res = mpc.step(seen.t_s, VehicleSample.of(seen), ref, mu=state_mu(seen.mu))
        solve.append((clock() - t0) * 1e3 if clock is not None else math.nan)
        v_ref, a_ref = speed_ref.at(seen.x, seen.y)
        drive = pid.step(v_ref, seen.vx, dt, a_ref)
        a = alloc.allocate(drive.torque_nm, res.yaw_moment, fz, fy, mu, WheelMotion.of(seen))
        if hasattr(mpc, "report_delivered"):
            mpc.report_delivered(res.yaw_moment - a.unmet_yaw_moment_nm)
        for name in STATE_FIELDS + WHEEL_FIELDS:
            st[name].append(getattr(out, name))           # as floats at the end
        for name in MPC_FIELDS:
            mp[name].append(getattr(res, name))
        status.append(res.solver_status)
        force.append(drive.force_n)
        torque.append(drive.torque_nm)
        wcmd.append(np.array(a.torque_nm, dtype=float))
        d_f, d_r, t_w = sensors.act((res.delta_front, res.delta_rear, a.torque_nm))
        out = sim.step(d_f, d_r, t_w, dt)
        k += 1
        done, reason = scenario.check_end(out, abort)
    if not done:
        reason = f"max_steps = {max_steps} reached"
    log = ClosedLoopLog(
        scenario=scenario.name, controller=mpc_cfg.controller, allocation=alloc_cfg.method,
        reference=ref,
        state={k_: np.array(v, dtype=float) for k_, v in st.items()},
        mpc={k_: np.array(v) for k_, v in mp.items()},
        solver_status=status,
        drive_force_n=np.array(force), drive_torque_nm=np.array(torque),
        wheel_torque_cmd_nm=np.array(wcmd).reshape(-1, 4), solve_ms=np.array(solve),
        completed=bool(done and not reason.startswith("aborted")), reason=reason,
        summary=scenario.summary(), lanes=scenario.path.lanes,
        vehicle_width_m=scenario.path.vehicle_width_m,
    )
    return log
