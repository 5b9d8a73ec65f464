"""Every fourws interface round-trips through rclpy serialization with non-default values."""

from __future__ import annotations

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message

from fourws_msgs.msg import (
    DriveCommand,
    MpcCommand,
    MpcDiagnostics,
    ReferenceTrajectory,
    VehicleState,
    WheelTorques,
)

ALL = [VehicleState, ReferenceTrajectory, MpcCommand, MpcDiagnostics, DriveCommand, WheelTorques]


def _fill(msg, rng):
    """Give every field of msg a non-default value, recursively; return the values set."""
    for name, typ in msg.get_fields_and_field_types().items():
        cur = getattr(msg, name)
        if typ == "std_msgs/Header":
            cur.stamp.sec, cur.stamp.nanosec, cur.frame_id = 12, 345_000_000, "map"
        elif typ == "double":
            setattr(msg, name, float(rng.uniform(-100, 100)))
        elif typ == "double[4]":
            setattr(msg, name, rng.uniform(-100, 100, 4))
        elif typ == "sequence<double>":
            setattr(msg, name, rng.uniform(-100, 100, 7).tolist())
        elif typ == "string":
            setattr(msg, name, "value_" + name)
        elif typ == "boolean":
            setattr(msg, name, True)
        elif typ in ("uint8", "uint32"):
            setattr(msg, name, 17)
        else:
            raise AssertionError(f"untested field type {typ} of {name}")
    return msg


@pytest.mark.parametrize("cls", ALL, ids=lambda c: c.__name__)
def test_roundtrip_every_field(cls):
    msg = _fill(cls(), np.random.default_rng(7))
    back = deserialize_message(serialize_message(msg), cls)
    for name in cls.get_fields_and_field_types():
        a, b = getattr(msg, name), getattr(back, name)
        if isinstance(a, np.ndarray | list) or hasattr(a, "__array__"):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        else:
            assert a == b, name
    assert back != cls()
