"""Converts the plant's outputs to standard ROS messages: the plant node's second job, kept apart.

``fill_odom`` and ``fill_imu`` refill messages built once (every field is set before each
publish, which serialises at once); ``reference_messages`` builds the scenario's reference
once. Frames: the pose in ``map``, the twist and the IMU in ``base_link`` (REP 105), yaw only
(a level car). The standard topics: docs/plant.md, "The plant node".
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry, Path
from sensor_msgs.msg import Imu, JointState

from fourws_msgs.msg import ReferenceTrajectory


def _yaw_quaternion(yaw: float) -> tuple[float, float]:
    """(z, w) of the rotation by ``yaw`` (rad) about the vertical axis."""
    return math.sin(0.5 * yaw), math.cos(0.5 * yaw)


def fill_odom(odom: Odometry, o: Any) -> Odometry:
    """Pose (x, y, yaw) and body-frame twist (v_x, v_y, r) of the plant outputs ``o``
    (``PlantOutputs`` or what the sensors made of it) into ``odom``; the header is the
    caller's."""
    odom.pose.pose.position.x, odom.pose.pose.position.y = o.x, o.y
    (odom.pose.pose.orientation.z,
     odom.pose.pose.orientation.w) = _yaw_quaternion(o.yaw)
    odom.twist.twist.linear.x, odom.twist.twist.linear.y = o.vx, o.vy
    odom.twist.twist.angular.z = o.yaw_rate
    return odom


def fill_imu(imu: Imu, joints: JointState, o: Any, gravity_mps2: float) -> None:
    """An IMU's yaw rate, specific force (a_x, a_y and, on a level car, gravity) and
    orientation, and the joints' steering angles (front, rear) and wheel speeds, from the
    plant outputs ``o``; the stamps are the caller's."""
    imu.angular_velocity.z = o.yaw_rate
    imu.linear_acceleration.x, imu.linear_acceleration.y = o.ax, o.ay
    imu.linear_acceleration.z = gravity_mps2
    imu.orientation.z, imu.orientation.w = _yaw_quaternion(o.yaw)
    joints.position = [o.steer_front, o.steer_rear, 0.0, 0.0, 0.0, 0.0]
    joints.velocity = [0.0, 0.0, *(float(w) for w in o.wheel_speed)]


def reference_messages(ref: Any, pose_spacing_m: float) -> tuple[ReferenceTrajectory, Path]:
    """The scenario's reference ``ref`` (x, y, yaw, curvature, speed arrays) whole as a
    ReferenceTrajectory, and as a nav_msgs/Path for viewers with a pose about every
    ``pose_spacing_m`` of arc length."""
    msg = ReferenceTrajectory()
    msg.header.frame_id = "map"
    msg.x, msg.y = ref.x.tolist(), ref.y.tolist()
    msg.yaw, msg.curvature = ref.yaw.tolist(), ref.curvature.tolist()
    msg.speed = ref.speed.tolist()
    path = Path()
    path.header.frame_id = "map"
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(ref.x), np.diff(ref.y)))])
    keep = np.unique(np.searchsorted(s, np.arange(0.0, s[-1], pose_spacing_m)))
    for i in keep:
        pose = PoseStamped()
        pose.header.frame_id = "map"
        pose.pose.position.x, pose.pose.position.y = float(ref.x[i]), float(ref.y[i])
        pose.pose.orientation.z, pose.pose.orientation.w = _yaw_quaternion(float(ref.yaw[i]))
        path.poses.append(pose)
    return msg, path
