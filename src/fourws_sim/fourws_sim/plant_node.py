"""Runs the fourws_sim core as the vehicle on the ROS graph.

Publishes ``/vehicle/state``, ``/clock``, ``/vehicle/odom`` every step (in that order: the
state starts the control chain) and the scenario's ``/reference/trajectory`` and
``/reference/path`` once (transient_local); ``/run/status`` (JSON: state, steps, simulated and
wall time) at the start, every ``status_period_s`` of wall time while running, and at the end.
Subscribes ``/control/mpc_command`` (δf, δr) and ``/control/wheel_torques``
(docs/plant.md, "The plant node").

The bench's plant side (``fourws_sim.core.sensing.Sensors``, set by a run's condition;
docs/plant.md, "Sensing and localisation"): seeded white or Gauss-Markov noise per channel
(``noise_sigma``, ``noise_tau_s``, ``noise_seed``), with ``tyre_forces: estimated`` zero tyre
force, load and adhesion fields, with ``localisation: ekf`` a localisation filter's pose in
place of the raw fix; commands act ``delay_periods`` steps late, the steering after
``steer_dead_time_s`` more. ``publish_ground_truth`` adds the true state on
``/vehicle/ground_truth`` (scored instead of the sensed one). ``vehicle_overrides`` changes
the plant's vehicle (not the controllers'). All defaults are the paper's ideal setting.

Timing modes (docs/graph.md, "Timing"):
- ``lockstep`` (default): publish the state for step k, wait until the MpcCommand and the
  WheelTorques stamped k are both held, then integrate to k+1; meanwhile the state is
  republished every ``republish_period_s``. No command for ``command_timeout_s`` ends the run.
- ``realtime``: step on a 10 ms steady-clock timer with the latest valid commands; a command
  older than ``command_max_age_s`` counts as late (``late_commands``), older than
  ``command_hold_timeout_s`` the plant holds safe (steer held, every wheel torque 0,
  ``safe_hold_steps``); a tick later than 1.5 periods is an ``overrun``. The timer starts
  once the first state is answered.

Both modes hold the first state until ``/vehicle/state`` has ``wait_for_subscribers``
subscribers. Every timer runs on the steady clock (the plant is the /clock source).

End of a run (docs/graph.md, "Lifecycle and bad input"): the final ``/run/status``, a linger
until every reliable subscriber has acknowledged it (at most ``linger_timeout_s``), the same
status as JSON to ``status_file`` (if set), and an exit with
:class:`fourws_common.exit_codes.ExitCode` COMPLETED (0), ABORTED (3: left the road,
``abort_lateral_error_m``, or spun, ``abort_sideslip_deg``) or TIMEOUT (4: commands did not
arrive); the reason is logged and published on ``/run/status``.

Bad input: a NaN/inf command, or one beyond ``fourws_common.input_guard.COMMAND_LIMITS``, is
rejected and the last valid one held (counted, logged at most once per second); angles beyond
the actuator limits are clipped with a warning; in lockstep a command stamped for another step
is ignored.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import time
from types import SimpleNamespace
from typing import Any

import numpy as np
from nav_msgs.msg import Odometry, Path
from rclpy.clock import Clock as RclClock
from rclpy.clock import ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import String

from fourws_common.conversions import (
    RateLimitedLog,
    fill_vehicle_state,
    ns_to_stamp,
    stamp_to_ns,
)
from fourws_common.exit_codes import ExitCode
from fourws_common.health import WARN, NodeHealth, Runtime
from fourws_common.input_guard import COMMAND_LIMITS, implausible_fields
from fourws_common.node_main import run_node
from fourws_common.qos import qos_of
from fourws_common.ros_params import ParamBinding
from fourws_common.topics import (
    CLOCK,
    MPC_COMMAND,
    REFERENCE_PATH,
    REFERENCE_TRAJECTORY,
    RUN_STATUS,
    VEHICLE_GROUND_TRUTH,
    VEHICLE_IMU,
    VEHICLE_JOINT_STATES,
    VEHICLE_ODOM,
    VEHICLE_STATE,
    WHEEL_TORQUES,
)
from fourws_common.wheels import JOINT_NAMES
from fourws_msgs.msg import MpcCommand, ReferenceTrajectory, VehicleState, WheelTorques
from fourws_sim.core.scenario import AbortLimits, load_scenario
from fourws_sim.core.sensing import sensors_from_params
from fourws_sim.core.simulator import Simulator
from fourws_sim.plant_config import PlantNodeConfig
from fourws_sim.plant_messages import fill_imu, fill_odom, reference_messages

#: Wall period (s, steady clock) at which a waiting plant checks whether its graph is complete.
START_CHECK_PERIOD_S = 0.01


#: the /diagnostics kind of a command refused as not finite or beyond COMMAND_LIMITS
REJECTED_COMMAND = "rejected_command"

#: the parameters the run is built from at start (the others apply from the next step)
START_ONLY = ("scenario", "mode", "dt_s", "substep_s", "status_period_s", "path_pose_spacing_m",
              "noise_sigma", "noise_tau_s", "noise_seed", "delay_periods", "steer_dead_time_s",
              "tyre_forces", "localisation", "vehicle_file", "vehicle_overrides",
              "publish_ground_truth", "publish_standard_sensors")


class PlantNode(Node):
    """Wires the plant core to topics; all physics is in fourws_sim.core."""

    def __init__(self) -> None:
        super().__init__("plant_node")
        self.params = ParamBinding(self, PlantNodeConfig, on_change=self._on_params)
        self._start_cfg = self.params.config
        cfg = self.params.config
        self.scenario = load_scenario(cfg.scenario, vehicle=cfg.vehicle_file or None
                                      ).with_vehicle_overrides(cfg.vehicle_overrides)
        self.abort = AbortLimits.of(cfg.abort_lateral_error_m, cfg.abort_sideslip_deg)
        self.sim = Simulator.from_scenario(self.scenario, substep_s=cfg.substep_s,
                                           steer_dead_time_s=cfg.steer_dead_time_s)
        self.sim.warm_up(cfg.dt_s)
        self.sensors = sensors_from_params(dataclasses.asdict(cfg), cfg.dt_s,
                                           initial_command=((0.0, 0.0), np.zeros(4)))
        self.dt_ns = int(round(cfg.dt_s * 1e9))
        self.step_k = 0
        self.done = False
        self.ended = False
        # until the run ends (_finish), a stop by SIGINT/SIGTERM is an interrupted run
        self.exit_code = int(ExitCode.INTERRUPTED)
        self.steer_cmd = (0.0, 0.0)
        self.torque_cmd = np.zeros(4)
        self.pending_cmd: MpcCommand | None = None
        self.pending_torque: WheelTorques | None = None
        # realtime: stamps (ns) of the held commands, and the honesty counters
        self.cmd_stamp_ns: int | None = None
        self.torque_stamp_ns: int | None = None
        self._rt_timer = None  # the 10 ms step timer, from the first state's answer on
        self.health = NodeHealth(self)
        self.health.runtime(self._runtime)
        self._reported = (0, 0)   # overruns, late commands at the last runtime report
        self.late_commands = 0
        self.safe_hold_steps = 0
        self.overruns = 0
        self.in_safe_hold = False
        self.last_tick: float | None = None
        self._steady = RclClock(clock_type=ClockType.STEADY_TIME)
        self.last_progress = time.monotonic()
        self.last_publish = time.monotonic()
        log = self.get_logger()
        self.stamp_log = RateLimitedLog(log.warning)
        self.clip_log = RateLimitedLog(log.warning)
        self.late_log = RateLimitedLog(log.warning)

        self.pub_state = self.create_publisher(VehicleState, VEHICLE_STATE.ros_name,
                                               qos_of(VEHICLE_STATE))
        self.pub_odom = self.create_publisher(Odometry, VEHICLE_ODOM.ros_name, qos_of(VEHICLE_ODOM))
        self.pub_truth = None
        if cfg.publish_ground_truth:
            self.pub_truth = self.create_publisher(VehicleState, VEHICLE_GROUND_TRUTH.ros_name,
                                                   qos_of(VEHICLE_GROUND_TRUTH))
            self._truth_msg = VehicleState()
            self._truth_msg.header.frame_id = "map"
        self.pub_imu = self.pub_joints = None
        if cfg.publish_standard_sensors:
            self.pub_imu = self.create_publisher(Imu, VEHICLE_IMU.ros_name, qos_of(VEHICLE_IMU))
            self.pub_joints = self.create_publisher(JointState, VEHICLE_JOINT_STATES.ros_name,
                                                    qos_of(VEHICLE_JOINT_STATES))
            self._imu_msg = Imu()
            self._imu_msg.header.frame_id = "base_link"
            self._joints_msg = JointState()
            self._joints_msg.name = list(JOINT_NAMES)
        self.pub_clock = self.create_publisher(Clock, CLOCK.ros_name, qos_of(CLOCK))
        self.pub_ref = self.create_publisher(ReferenceTrajectory, REFERENCE_TRAJECTORY.ros_name,
                                             qos_of(REFERENCE_TRAJECTORY))
        self.pub_path = self.create_publisher(Path, REFERENCE_PATH.ros_name, qos_of(REFERENCE_PATH))
        self.pub_status = self.create_publisher(String, RUN_STATUS.ros_name, qos_of(RUN_STATUS))
        # Per-step messages are built once and refilled: every field is set before each
        # publish (which serialises at once), and Odometry's constructor alone costs ~40 µs.
        self._state_msg = VehicleState()
        self._state_msg.header.frame_id = "map"
        self._clock_msg = Clock()
        self._odom_msg = Odometry()
        self._odom_msg.header = self._state_msg.header
        self._odom_msg.child_frame_id = "base_link"
        self.create_subscription(MpcCommand, MPC_COMMAND.ros_name, self._on_mpc,
                                 qos_of(MPC_COMMAND))
        self.create_subscription(WheelTorques, WHEEL_TORQUES.ros_name, self._on_torques,
                                 qos_of(WHEEL_TORQUES))

        log.info(f"scenario '{self.scenario.name}': {self.scenario.summary()}")
        log.info(f"mode {cfg.mode}, dt {cfg.dt_s} s, substep {cfg.substep_s} s")
        if not self.sensors.ideal or cfg.steer_dead_time_s or cfg.vehicle_overrides:
            log.info(f"bench: noise on {sorted(self.sensors.noise.specs) or 'no channel'} "
                     f"(seed {cfg.noise_seed}), delay {cfg.delay_periods} periods, steering "
                     f"dead time {cfg.steer_dead_time_s * 1e3:g} ms, tyre data "
                     f"{cfg.tyre_forces}, localisation {cfg.localisation}, vehicle overrides "
                     f"{cfg.vehicle_overrides or 'none'}")
        # monotonic s: the first state published; the publication of the first state that was
        # answered (the run's wall time counts from here; the wait between the two is start-up:
        # nodes still discovering each other).
        self.start_wall: float | None = None
        self.answered_wall: float | None = None
        self._publish_reference()
        self._publish_status("running", "")
        self.outputs = self.sim.outputs()
        self.seen = self.sensors.measure(self.outputs)  # what /vehicle/state carries
        self.started = False
        # Steady-clock timers: the plant is the /clock source, so a timer on ROS time would
        # wait for itself under use_sim_time.
        self.create_timer(min(cfg.republish_period_s, 0.1), self._watchdog, clock=self._steady)
        self.create_timer(cfg.status_period_s, self._status_heartbeat, clock=self._steady)
        if cfg.wait_for_subscribers == 0:
            self._start()
        else:  # the graph is checked every 10 ms until it is complete (start-up time only)
            self._start_timer = self.create_timer(START_CHECK_PERIOD_S, self._start_check,
                                                  clock=self._steady)

    # -- parameters ----------------------------------------------------------------------
    def _on_params(self, cfg: PlantNodeConfig) -> None:
        # What the run was built from is fixed: the plant runs one scenario per process, so a
        # change would never apply (dt_s or mode changed mid-run once broke the run). A
        # ValueError makes ParamBinding answer the set as failed, naming why.
        fixed = [f"{n} = {getattr(cfg, n)!r}" for n in START_ONLY
                 if getattr(cfg, n) != getattr(self._start_cfg, n)]
        if fixed:
            raise ValueError(f"{', '.join(fixed)}: fixed at start (one run per plant "
                             "process): restart the plant to change it")
        self.abort = AbortLimits.of(cfg.abort_lateral_error_m, cfg.abort_sideslip_deg)
        self.get_logger().info("parameters updated: they apply from the next step")

    # -- inputs --------------------------------------------------------------------------
    def _valid_cmd(self, msg: MpcCommand) -> bool:
        bad = implausible_fields(msg, ("delta_front", "delta_rear", "yaw_moment"),
                                 COMMAND_LIMITS)
        if not bad:
            return True
        self.health.reject(REJECTED_COMMAND, self._now_ns(), f"rejected mpc_command: "
                           f"{', '.join(bad)}; holding the last valid steer command "
                           f"{self.steer_cmd}")
        return False

    def _valid_torques(self, msg: WheelTorques) -> np.ndarray | None:
        """The message's torques as a new (4,) array, N·m, or None (logged) if not finite or
        beyond :data:`~fourws_common.input_guard.COMMAND_LIMITS`."""
        t = np.array(msg.torque, dtype=float)
        bad = (["torque: not 4 values"] if t.shape != (4,) else
               implausible_fields(SimpleNamespace(torque=t), ("torque",), COMMAND_LIMITS))
        if not bad:
            return t
        self.health.reject(REJECTED_COMMAND, self._now_ns(), f"rejected wheel_torques: "
                           f"{', '.join(bad)}; holding the last valid torques")
        return None

    def _command_stamp(self, msg: Any, what: str, held_ns: int | None) -> int | None:
        """The stamp of a command to take, or None (logged where it is news) to ignore it.
        Lockstep: only the current step's. Realtime: not ahead of the plant, and not older
        than the command held (out of order)."""
        if self.ended:
            return None
        stamp = stamp_to_ns(msg.header.stamp)
        now = self.step_k * self.dt_ns
        if stamp > now:            # no controller answers a state not yet published
            self.health.reject("future_stamp", self._now_ns(), f"ignored {what} stamped "
                               f"{stamp} ns: ahead of the plant (step {self.step_k})")
            return None
        if self.params.config.mode != "realtime":
            if stamp != now:       # an answer to a state republished before the step: a repeat
                self.stamp_log(self._now_ns(), f"ignored {what} stamped {stamp} ns while at "
                               f"step {self.step_k}")
                return None
            return stamp
        if held_ns is not None and stamp < held_ns:
            return None
        return stamp

    def _on_mpc(self, msg: MpcCommand) -> None:
        stamp = self._command_stamp(msg, "mpc_command", self.cmd_stamp_ns)
        if stamp is None:
            return
        if self.params.config.mode == "realtime":
            if self._valid_cmd(msg):
                self.steer_cmd = (msg.delta_front, msg.delta_rear)
                self.cmd_stamp_ns = stamp
                self._realtime_answered()
            return
        self.pending_cmd = msg
        self._try_step()

    def _on_torques(self, msg: WheelTorques) -> None:
        stamp = self._command_stamp(msg, "wheel_torques", self.torque_stamp_ns)
        if stamp is None:
            return
        if self.params.config.mode == "realtime":
            if (t := self._valid_torques(msg)) is not None:
                self.torque_cmd = t
                self.torque_stamp_ns = stamp
                self._realtime_answered()
            return
        self.pending_torque = msg
        self._try_step()

    # -- stepping ------------------------------------------------------------------------
    def _try_step(self) -> None:
        if self.pending_cmd is None or self.pending_torque is None:
            return
        if self._valid_cmd(self.pending_cmd):
            self.steer_cmd = (self.pending_cmd.delta_front, self.pending_cmd.delta_rear)
        if (t := self._valid_torques(self.pending_torque)) is not None:
            self.torque_cmd = t
        self.pending_cmd = None
        self.pending_torque = None
        self._advance()

    def _advance(self, torque: np.ndarray | None = None) -> None:
        cfg = self.params.config
        if self.answered_wall is None:
            self.answered_wall = self.last_publish
        steer, torques = self.sensors.act(
            (self.steer_cmd, self.torque_cmd if torque is None else torque))
        self.outputs = self.sim.step(steer[0], steer[1], torques, dt_s=cfg.dt_s)
        self.seen = self.sensors.measure(self.outputs)  # one noise draw per new state
        self._warn_clipping()
        self.step_k += 1
        self.last_progress = time.monotonic()
        ended, reason, completed = self._end_check()
        self._publish_state()
        if ended:
            self._finish(completed, reason)

    def _warn_clipping(self) -> None:
        if self.sim.last_clipped:
            df, dr = self.steer_cmd
            self.clip_log(self._now_ns(), f"commands beyond the actuator limits clipped: "
                          f"{', '.join(self.sim.last_clipped)} (steer command "
                          f"{math.degrees(df):.2f}°, {math.degrees(dr):.2f}°)")

    def _end_check(self) -> tuple[bool, str, bool]:
        ended, reason = self.scenario.check_end(self.outputs, self.abort)
        return ended, reason, ended and not reason.startswith("aborted")

    def _runtime(self) -> Runtime:
        """The run's progress and, in realtime, its timing honesty: WARN while in safe hold
        or when periods were overrun or commands came late since the last report."""
        rt = Runtime(values={"state": ("ended" if self.ended else "running" if self.started
                                       else "waiting for subscribers"),
                             "steps": str(self.step_k), "overruns": str(self.overruns),
                             "late_commands": str(self.late_commands),
                             "safe_hold_steps": str(self.safe_hold_steps)})
        new = (self.overruns - self._reported[0], self.late_commands - self._reported[1])
        self._reported = (self.overruns, self.late_commands)
        problems = [f"{n} {what}" for n, what in zip(new, ("period(s) overrun",
                                                          "late command(s)"), strict=True) if n]
        if self.in_safe_hold:
            problems.insert(0, "safe hold: no fresh commands")
        if problems:
            rt.level, rt.message = WARN, "; ".join(problems) + " since the last report"
        return rt

    def _status_heartbeat(self) -> None:
        if self.start_wall is not None and not self.ended:
            self._publish_status("running", "")

    def _start(self) -> None:
        cfg = self.params.config
        self.started = True
        self.start_wall = time.monotonic()
        self.last_progress = self.start_wall
        if cfg.wait_for_subscribers:
            self.get_logger().info("all subscribers present: starting")
        self._publish_state()

    def _realtime_answered(self) -> None:
        """Realtime: start the step timer once the first state's commands are both held."""
        if (self._rt_timer is None and self.started and not self.ended
                and None not in (self.cmd_stamp_ns, self.torque_stamp_ns)):
            self._rt_timer = self.create_timer(self.params.config.dt_s, self._realtime_tick,
                                               clock=self._steady)

    def _realtime_tick(self) -> None:
        if self.ended:
            return
        cfg = self.params.config
        now = time.monotonic()
        if self.last_tick is not None and now - self.last_tick > 1.5 * cfg.dt_s:
            self.overruns += max(1, int((now - self.last_tick) / cfg.dt_s) - 1)  # periods lost
        self.last_tick = now
        t_ns = self.step_k * self.dt_ns
        held = [self.cmd_stamp_ns, self.torque_stamp_ns]
        age_s = ((t_ns - min(held)) * 1e-9 if None not in held
                 else (now - (self.start_wall or now)))
        torque = None
        if age_s > cfg.command_max_age_s:
            self.late_commands += 1
            self.late_log(t_ns, f"commands {age_s * 1e3:.0f} ms old at step {self.step_k} "
                          f"(limit {cfg.command_max_age_s * 1e3:.0f} ms)")
        if age_s > cfg.command_hold_timeout_s:
            if not self.in_safe_hold:
                self.get_logger().warning(
                    f"safe hold at step {self.step_k}: newest commands {age_s:.2f} s old; "
                    "steer held, wheel torques 0 until fresh commands arrive")
            self.in_safe_hold = True
            self.safe_hold_steps += 1
            torque = np.zeros(4)
        elif self.in_safe_hold:
            self.in_safe_hold = False
            self.get_logger().info(f"fresh commands at step {self.step_k}: safe hold ended")
        self._advance(torque)

    def _start_check(self) -> None:
        """Start once the graph is complete: every subscriber present and holding the
        reference (a controller that stays up across runs resets on it and answers state 0
        with the new path)."""
        if self.started or self.ended:
            self._start_timer.cancel()
            return
        cfg = self.params.config
        zero = Duration(seconds=0)
        if (self.pub_state.get_subscription_count() >= cfg.wait_for_subscribers
                and self.pub_ref.get_subscription_count()
                >= cfg.wait_for_reference_subscribers
                and self.pub_ref.wait_for_all_acked(zero)):
            self._start_timer.cancel()
            self._start()

    def _watchdog(self) -> None:
        if self.ended:
            return
        cfg = self.params.config
        now = time.monotonic()
        if not self.started:
            return
        realtime = cfg.mode == "realtime"
        if self._rt_timer is not None:
            return  # realtime and stepping: its timer holds safe when commands stop
        if now - self.last_progress > cfg.command_timeout_s:
            missing = [name for name, held in (
                (MPC_COMMAND.name, self.cmd_stamp_ns if realtime else self.pending_cmd),
                (WHEEL_TORQUES.name, self.torque_stamp_ns if realtime else self.pending_torque))
                if held is None]
            self._finish(False, f"no {' and '.join(missing)} for step {self.step_k} within "
                         f"{cfg.command_timeout_s:.1f} s", ExitCode.TIMEOUT)
            return
        if now - self.last_publish > cfg.republish_period_s:
            self._publish_state()

    def _finish(self, completed: bool, reason: str, code: ExitCode | None = None) -> None:
        self.get_logger().info(
            f"run ended at t = {self.outputs.t_s:.2f} s after {self.step_k} steps: {reason}")
        if code is None:
            code = ExitCode.COMPLETED if completed else ExitCode.ABORTED
        self.exit_code = int(code)
        self.final_status = self._publish_status("ended", reason, completed)
        self.ended = True
        # Linger until every reliable subscriber (recorder, runner) has acknowledged the
        # final state and status, so none of them depends on the timing of the exit.
        self._linger_deadline = time.monotonic() + self.params.config.linger_timeout_s
        self._exit_timer = self.create_timer(0.02, self._linger, clock=self._steady)

    def _linger(self) -> None:
        zero = Duration(seconds=0)
        pubs = [self.pub_state, self.pub_status] + ([self.pub_truth] if self.pub_truth else [])
        acked = all(p.wait_for_all_acked(zero) for p in pubs)
        if not acked and time.monotonic() < self._linger_deadline:
            return
        self._exit_timer.cancel()
        waited = self.params.config.linger_timeout_s - (self._linger_deadline - time.monotonic())
        if acked:
            self.get_logger().info(f"final state and status acknowledged after {waited:.2f} s")
        else:
            self.get_logger().warning(f"final state or status not acknowledged by every "
                                      f"subscriber within {waited:.2f} s; exiting")
        self._write_status_file()
        self.done = True

    def _write_status_file(self) -> None:
        path = self.params.config.status_file
        if not path:
            return
        tmp = f"{path}.tmp{os.getpid()}"
        try:
            with open(tmp, "w", encoding="utf-8") as fh:
                json.dump(self.final_status, fh)
            os.replace(tmp, path)
        except OSError as exc:
            self.get_logger().error(f"could not write status_file {path}: {exc}")

    # -- outputs -------------------------------------------------------------------------
    def _now_ns(self) -> int:
        return self.step_k * self.dt_ns

    def _publish_state(self) -> None:
        stamp = ns_to_stamp(self.step_k * self.dt_ns)
        msg = self._state_msg
        msg.header.stamp = stamp
        fill_vehicle_state(msg, self.seen)
        # The state starts the control chain (in lockstep the next step waits on it): it
        # goes first, so the controllers compute while /clock and /vehicle/odom go out.
        self.pub_state.publish(msg)
        if self.pub_truth is not None:
            truth = self._truth_msg
            truth.header.stamp = stamp
            fill_vehicle_state(truth, self.outputs)
            self.pub_truth.publish(truth)
        self._clock_msg.clock = stamp
        self.pub_clock.publish(self._clock_msg)
        self.pub_odom.publish(fill_odom(self._odom_msg, self.seen))
        if self.pub_imu is not None:
            imu, joints = self._imu_msg, self._joints_msg
            imu.header.stamp = joints.header.stamp = stamp
            fill_imu(imu, joints, self.seen, self.scenario.vehicle.gravity_mps2)
            self.pub_imu.publish(imu)
            self.pub_joints.publish(joints)
        self.last_publish = time.monotonic()

    def _publish_reference(self) -> None:
        msg, path = reference_messages(self.scenario.path, self.params.config.path_pose_spacing_m)
        self.pub_ref.publish(msg)
        self.pub_path.publish(path)

    def _publish_status(self, state: str, reason: str, completed: bool = False) -> dict:
        """/run/status JSON. ``wall_time_s``: from the publication of the first state that
        was answered to now (the plant's own monotonic clock), so the real-time factor is in
        the bag and excludes start-up; ``startup_wait_s``: from the first state to that one
        (republished every ``republish_period_s`` until the graph has discovered itself)."""
        now = time.monotonic()
        origin = self.answered_wall if self.answered_wall is not None else self.start_wall
        wall = None if origin is None else now - origin
        startup = (None if self.start_wall is None or self.answered_wall is None
                   else self.answered_wall - self.start_wall)
        status = {
            "state": state, "completed": completed, "reason": reason, "steps": self.step_k,
            "sim_time_s": self.step_k * self.dt_ns * 1e-9, "scenario": self.scenario.name,
            "mode": self.params.config.mode,
            "rejected_commands": self.health.counts.get(REJECTED_COMMAND, 0),
            "wall_time_s": wall,
            "startup_wait_s": startup, "late_commands": self.late_commands,
            "safe_hold_steps": self.safe_hold_steps, "overruns": self.overruns,
        }
        if state == "ended":
            status["exit_code"] = self.exit_code
        self.pub_status.publish(String(data=json.dumps(status)))
        return status


def main(args: list[str] | None = None) -> int:
    return run_node(PlantNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
