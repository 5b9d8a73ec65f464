"""Declares the plant node's parameters (``plant_node``; defaults in ``config/plant.yaml``).

They cover the scenario, the timing mode, the run's end, and the bench's plant side
(measurement noise, delays, estimated tyre forces, localisation filter, plant overrides;
docs/graph.md, "Configuration"). Every field carries its descriptor
(``fourws_common.params.param``): range, unit, choices."""

from __future__ import annotations

from dataclasses import dataclass

from fourws_common.params import param
from fourws_sim.core.localisation import LOCALISATION_METHODS
from fourws_sim.core.sensing import CHANNELS, MAX_SEED, TYRE_SOURCES


@dataclass(frozen=True)
class PlantNodeConfig:
    scenario: str = param("dlc_60_mu05", "scenario name (config/scenarios) or path to a YAML")
    mode: str = param("lockstep", "timing mode", choices=("lockstep", "realtime"))
    dt_s: float = param(0.01, "control period", lo=0.001, hi=0.1, unit="s")
    substep_s: float = param(0.001, "RK4 integration substep", lo=1e-5, hi=0.01, unit="s")
    abort_lateral_error_m: float = param(5.0, "end the run beyond this lateral error",
                                         lo=0.1, hi=100.0, unit="m")
    abort_sideslip_deg: float = param(30.0, "end the run beyond this sideslip",
                                      lo=1.0, hi=90.0, unit="deg")
    command_timeout_s: float = param(20.0, "lockstep (realtime: the first state): end the run "
                                     "when a step's commands do not arrive within this wall "
                                     "time", lo=0.5, hi=600.0, unit="s")
    republish_period_s: float = param(0.25, "lockstep (realtime: the first state): publish the "
                                      "waiting state again after this wall time", lo=0.01,
                                      hi=10.0, unit="s")
    wait_for_subscribers: int = param(0, "hold the first state until /vehicle/state has this "
                                      "many subscribers (0: start at once)", lo=0, hi=100)
    wait_for_reference_subscribers: int = param(
        0, "also hold the first state until /reference/trajectory has this many subscribers "
        "(each has acknowledged the reference before the first state)", lo=0, hi=100)
    command_max_age_s: float = param(0.05, "realtime: warn about and count a command older "
                                     "than this (its stamp is the state it answered)",
                                     lo=0.0, hi=60.0, unit="s")
    command_hold_timeout_s: float = param(0.5, "realtime: safe hold (steer held, torques 0) "
                                          "while the newest command is older than this",
                                          lo=0.01, hi=600.0, unit="s")
    status_file: str = param("", "write the final /run/status JSON here before exiting "
                             "(empty: none)")
    linger_timeout_s: float = param(5.0, "at the end, wait at most this long for reliable "
                                    "subscribers to acknowledge the final state and status",
                                    lo=0.0, hi=60.0, unit="s")
    status_period_s: float = param(0.5, "publish a 'running' /run/status (steps, simulated "
                                   "and wall time) this often", lo=0.05, hi=60.0, unit="s")
    path_pose_spacing_m: float = param(0.5, "spacing of poses in /reference/path",
                                       lo=0.05, hi=10.0, unit="m")
    # -- the bench's plant side (core.sensing.Sensors; fourws_bringup's conditions set it)
    noise_sigma: tuple = param([0.0] * len(CHANNELS), "measurement noise sigma per channel "
                               f"({', '.join(CHANNELS)}; SI units)", lo=0.0, hi=100.0)
    noise_tau_s: tuple = param([0.0] * len(CHANNELS), "Gauss-Markov correlation time per "
                               "channel (0: white)", lo=0.0, hi=1.0e4, unit="s")
    noise_seed: int = param(0, "seed of the measurement noise (a seed reproduces a run)",
                            lo=0, hi=MAX_SEED)
    delay_periods: int = param(0, "computation delay: a command answering the state of step "
                               "k acts from step k + N", lo=0, hi=100)
    steer_dead_time_s: float = param(0.0, "steering dead time before the actuator lag",
                                     lo=0.0, hi=1.0, unit="s")
    tyre_forces: str = param("oracle", "oracle: /vehicle/state carries the true tyre forces, "
                             "loads and adhesion (the paper's idealised setting); estimated: "
                             "those fields are 0 (no car measures them)", choices=TYRE_SOURCES)
    localisation: str = param("none", "the pose the controllers receive: none, the measured "
                              "state; ekf, a localisation filter that knows the noise's "
                              "models (core.localisation)", choices=LOCALISATION_METHODS)
    vehicle_file: str = param("", "car file: a name in fourws_common/config/vehicles or a "
                              "path; empty: the paper's car (read at start)")
    vehicle_overrides: str = param("", "plant overrides over the scenario's vehicle, a YAML "
                                   "mapping of car-file fields (e.g. a slower steering "
                                   "actuator); empty: none")
    publish_ground_truth: bool = param(False, "also publish the true state on "
                                       "/vehicle/ground_truth (realistic conditions)")
    publish_standard_sensors: bool = param(False, "also publish the sensed state as a car's "
                                           "standard messages: /vehicle/imu (sensor_msgs/Imu) "
                                           "and /vehicle/joint_states (sensor_msgs/JointState; "
                                           "/vehicle/odom is always published), for the "
                                           "adapter node")

    def __post_init__(self) -> None:
        ratio = self.dt_s / self.substep_s
        if abs(ratio - round(ratio)) > 1e-9:
            raise ValueError(f"dt_s ({self.dt_s}) must be an integer multiple of substep_s "
                             f"({self.substep_s})")
