"""Conversions between fourws messages and plain numbers/arrays (the edge of every core).

Stamps are handled as integer nanoseconds so that step k of a 10 ms lockstep run is stamped
exactly ``k * 10_000_000`` ns and stamps compare equal across nodes (docs/graph.md,
"Topics (100 Hz, simulated time)").
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time

from fourws_msgs.msg import VehicleState

VEHICLE_SCALARS = (
    "x", "y", "yaw", "vx", "vy", "yaw_rate", "ax", "ay", "sideslip", "steer_front", "steer_rear",
)
VEHICLE_WHEEL_ARRAYS = ("wheel_speed", "wheel_torque", "fx", "fy", "fz", "mu")


def stamp_to_ns(stamp: Time) -> int:
    """builtin_interfaces/Time -> integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(ns: int) -> Time:
    """Integer nanoseconds -> builtin_interfaces/Time."""
    return Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))


def seconds_to_ns(t_s: float) -> int:
    """Seconds -> integer nanoseconds, rounded to the nearest nanosecond."""
    return int(round(t_s * 1e9))


def vehicle_state_to_dict(msg: VehicleState) -> dict[str, Any]:
    """VehicleState -> {field: float or ndarray(4)}, plus ``t_s`` from the stamp."""
    out: dict[str, Any] = {k: float(getattr(msg, k)) for k in VEHICLE_SCALARS}
    for k in VEHICLE_WHEEL_ARRAYS:
        out[k] = np.asarray(getattr(msg, k), dtype=float)
    out["t_s"] = stamp_to_ns(msg.header.stamp) * 1e-9
    return out


def fill_vehicle_state(msg: VehicleState, values: Mapping[str, Any] | Any) -> VehicleState:
    """Copy the VehicleState fields from a mapping or an object with those attributes."""
    get = values.__getitem__ if isinstance(values, Mapping) else lambda k: getattr(values, k)
    for k in VEHICLE_SCALARS:
        setattr(msg, k, float(get(k)))
    for k in VEHICLE_WHEEL_ARRAYS:
        setattr(msg, k, np.asarray(get(k), dtype=float).reshape(4))
    return msg


def non_finite_fields(msg: Any, names: tuple[str, ...]) -> list[str]:
    """Names of the listed (scalar or array) fields of ``msg`` that hold NaN or infinity."""
    bad = []
    for k in names:
        v = getattr(msg, k)
        if isinstance(v, float | int):
            if not math.isfinite(v):
                bad.append(k)
        elif not np.all(np.isfinite(np.asarray(v, dtype=float))):
            bad.append(k)
    return bad


class RateLimitedLog:
    """Count rejections and log at most once per ``period_s`` of the caller's clock."""

    def __init__(self, log_fn, period_s: float = 1.0) -> None:
        self._log = log_fn
        self._logger = getattr(log_fn, "__self__", None)
        self._level = getattr(log_fn, "__name__", "")
        self._period_ns = int(period_s * 1e9)
        self._last_ns: int | None = None
        self.count = 0

    def __call__(self, now_ns: int, text: str) -> None:
        self.count += 1
        last = self._last_ns
        # a clock that went back (a stray stamp, a new run) must not silence the log
        if last is None or now_ns - last >= self._period_ns or now_ns < last:
            self._emit(f"{text} (rejected {self.count} so far)")
            self._last_ns = now_ns

    def _emit(self, msg: str) -> None:
        # rclpy refuses one call site logging at two severities ("Logger severity cannot be
        # changed between calls"): each severity gets a line of its own.
        lg, level = self._logger, self._level
        if lg is None:
            self._log(msg)
        elif level == "error":
            lg.error(msg)
        elif level in ("warning", "warn"):
            lg.warning(msg)
        elif level == "info":
            lg.info(msg)
        else:
            self._log(msg)
