"""The wheel order of every per-wheel array and message field (pure Python, no ROS).

FL, FR, RL, RR = 0, 1, 2, 3 (docs/conventions.md, "Frames, signs, units"): the plant's wheel
arrays, the VehicleState and WheelTorques fields, the allocator's torques and the report's
columns all follow :class:`Wheel`.
"""

from __future__ import annotations

from enum import IntEnum


class Wheel(IntEnum):
    """Wheel indices, the order of every per-wheel array."""

    FL = 0
    FR = 1
    RL = 2
    RR = 3


WHEEL_SIDE = (1.0, -1.0, 1.0, -1.0)
"""+1 for the left wheels, −1 for the right wheels, in :class:`Wheel` order."""


STEER_JOINTS = ("steer_front", "steer_rear")
"""sensor_msgs/JointState names of the road-wheel steer angles (rad, left positive): the
plant's ``/vehicle/joint_states`` and the adapter's default."""
WHEEL_JOINTS = tuple(f"wheel_{w.name.lower()}" for w in Wheel)
"""JointState names of the wheel spin joints (rad/s as ``velocity``), in :class:`Wheel` order."""
JOINT_NAMES = (*STEER_JOINTS, *WHEEL_JOINTS)
