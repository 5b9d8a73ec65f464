"""The controllers' input from a car's standard messages (pure: numbers in, numbers out).

What each fourws controller reads of ``fourws_msgs/VehicleState`` (docs/controller-interface.md,
"Inputs"):

============  ==========================================  ======================================
field         MPC / speed PID / allocator                 standard source (``adapter_node``)
============  ==========================================  ======================================
x, y, yaw     MPC (path errors), PID (speed profile)      nav_msgs/Odometry pose (yaw from the
                                                          quaternion)
vx, vy        MPC, PID (vx)                               Odometry twist (body frame, REP 105)
yaw_rate      MPC                                         sensor_msgs/Imu angular_velocity.z (or
                                                          the Odometry twist)
ax, ay        allocator with estimated tyre data          Imu linear_acceleration x, y
steer_front,  MPC (prediction with actuator states)       sensor_msgs/JointState positions (mean
steer_rear                                                of the listed joints per axle)
fz, fy, mu    allocator (load-ratio allocation), MPC (μ)  estimated from ax, ay
                                                          (:class:`~fourws_torque_alloc.core.
                                                          tyre_estimate.TyreEstimator`), μ the
                                                          nominal
wheel_speed   (recorded, not used by a controller)        JointState velocities of the wheels
============  ==========================================  ======================================

Measured: pose, velocities, yaw rate, accelerations, steer angles, wheel speeds. Estimated:
tyre loads, lateral forces and adhesion (no car measures them).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from fourws_common.input_guard import implausible_fields
from fourws_common.wheels import STEER_JOINTS, WHEEL_JOINTS
from fourws_sim.core.plant_io import PlantOutputs
from fourws_torque_alloc.core.tyre_estimate import TyreEstimator


@dataclass(frozen=True)
class JointMap:
    """Which sensor_msgs/JointState names are the steer angles and the wheel spin rates."""

    steer_front: tuple[str, ...] = (STEER_JOINTS[0],)
    steer_rear: tuple[str, ...] = (STEER_JOINTS[1],)
    wheels: tuple[str, ...] = WHEEL_JOINTS

    def __post_init__(self) -> None:
        if not self.steer_front or not self.steer_rear:
            raise ValueError("steer joints: at least one joint per axle")
        if len(self.wheels) != 4:
            raise ValueError(f"wheel_joints: expected 4 names (FL FR RL RR), got "
                             f"{list(self.wheels)}")

    def read(self, names: Sequence[str], position: Sequence[float],
             velocity: Sequence[float]) -> tuple[float, float, np.ndarray]:
        """(steer front, steer rear (rad, mean per axle), wheel speeds (4,), rad/s).
        ValueError naming a missing joint or a missing position/velocity."""
        index = {n: i for i, n in enumerate(names)}
        missing = [n for n in (*self.steer_front, *self.steer_rear, *self.wheels)
                   if n not in index]
        if missing:
            raise ValueError(f"joint_states: no joint(s) {missing} (it has {list(names)})")

        def values(joints: tuple[str, ...], array: Sequence[float], what: str) -> list[float]:
            out = []
            for n in joints:
                if index[n] >= len(array):
                    raise ValueError(f"joint_states: no {what} for joint '{n}'")
                out.append(float(array[index[n]]))
            return out

        front = values(self.steer_front, position, "position")
        rear = values(self.steer_rear, position, "position")
        wheels = values(self.wheels, velocity, "velocity")
        return float(np.mean(front)), float(np.mean(rear)), np.asarray(wheels)


def yaw_of(qx: float, qy: float, qz: float, qw: float) -> float:
    """Heading (rad) of a unit quaternion: the z-y-x Euler yaw, atan2(2(wz + xy),
    1 - 2(y² + z²)). ValueError for a quaternion far from unit length."""
    n2 = qx * qx + qy * qy + qz * qz + qw * qw
    if not math.isfinite(n2) or abs(n2 - 1.0) > 1e-3:
        raise ValueError(f"odometry orientation is not a unit quaternion (|q|^2 = {n2:.6g})")
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def controller_input(pose: tuple[float, float, float, float, float, float, float],
                     twist: tuple[float, float, float], imu: tuple[float, float, float],
                     joints: tuple[Sequence[str], Sequence[float], Sequence[float]],
                     joint_map: JointMap, estimator: TyreEstimator,
                     yaw_rate_from: str = "imu", t_s: float = 0.0) -> PlantOutputs:
    """Every VehicleState field (:class:`~fourws_sim.core.plant_io.PlantOutputs`, the one
    type of them) at ``t_s``: ``pose`` = (x, y, z, qx, qy, qz, qw) of Odometry's pose,
    ``twist`` = (vx, vy, r) of its body-frame twist, ``imu`` = (r, ax, ay) of an Imu,
    ``joints`` = (name, position, velocity) of a JointState; wheel torques and longitudinal
    tyre forces, which nothing measures and no controller reads, are zero.
    ``yaw_rate_from``: ``imu`` or ``odom``. ValueError for a non-finite value, naming it."""
    x, y, _z, qx, qy, qz, qw = (float(v) for v in pose)
    vx, vy, r_odom = (float(v) for v in twist)
    r_imu, ax, ay = (float(v) for v in imu)
    named = {"x": x, "y": y, "vx": vx, "vy": vy, "ax": ax, "ay": ay,
             "yaw_rate": r_imu if yaw_rate_from == "imu" else r_odom}
    bad = [k for k, v in named.items() if not math.isfinite(v)]
    if bad:
        raise ValueError(f"non-finite {', '.join(bad)}")
    yaw = yaw_of(qx, qy, qz, qw)
    steer_f, steer_r, wheels = joint_map.read(*joints)
    if not all(math.isfinite(v) for v in (steer_f, steer_r, *wheels)):
        raise ValueError("non-finite joint position or velocity")
    bad = implausible_fields(SimpleNamespace(**named, steer_front=steer_f, steer_rear=steer_r,
                                             wheel_speed=wheels), (*named, "steer_front",
                                                                   "steer_rear", "wheel_speed"))
    if bad:          # finite but absurd (an IMU's 1e308 m/s² made the tyre estimate inf)
        raise ValueError(f"implausible {', '.join(bad)}")
    fz, fy, mu = estimator.estimate(ax, ay)
    return PlantOutputs(t_s, x, y, yaw, vx, vy, named["yaw_rate"], ax, ay, math.atan2(vy, vx),
                        steer_f, steer_r, wheels, np.zeros(4), np.zeros(4), fy, fz, mu)
