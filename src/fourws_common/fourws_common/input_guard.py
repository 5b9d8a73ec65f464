"""Input checks shared by every node (pure Python + numpy, no ROS): plausible values, stamps.

A node checks each message at its edge, before any value reaches a core or an integrator
(docs/graph.md, "Lifecycle and bad input"):

- :func:`implausible_fields` — a field that is not finite or lies outside the physical range
  of :data:`STATE_LIMITS` (a finite 1.7e308 m/s is as wrong as NaN: it overflows the first
  product it enters);
- :func:`check_reference` — a reference trajectory with non-finite or absurd samples, or
  repeated points (the one check of every node that takes a reference);
- :class:`StampGate` — stamps must move forward by at most ``max_jump_ns``; an equal stamp is
  a repeat (lockstep republishes), an older one or a jump far ahead is rejected, *not*
  adopted as the new "last" (one stray message never locks a node out of later input). A
  jump (forward, or back to an earlier time: a restarted plant or bag) that the next stamp
  confirms — it follows the jumped stamp by 0..``max_jump_ns`` — is a new timeline: the gate
  accepts it and reports ``JUMPED`` so the node can reset its state; in the nodes only once
  the old timeline has been silent for :data:`TIMELINE_QUIET_NS` (strays in a row never move
  a run off a plant that is still publishing). A timeline that has just come back from such
  a silence (the node stalled: the states it handles first were sent before the stall) is
  no proof of life for a jump *ahead* during the next ``quiet_ns``: the plant's newest
  states, ahead by the stall, are taken at the first confirmation, not 1 s later.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from enum import Enum
from typing import Any

import numpy as np

from fourws_common.params import param

#: Physical ranges (inclusive) of VehicleState fields, SI. Generous for any road car; a value
#: outside is a broken sensor, a unit error or a fault injection.
STATE_LIMITS: dict[str, tuple[float, float]] = {
    "x": (-1e6, 1e6),            # m
    "y": (-1e6, 1e6),            # m
    "yaw": (-1e4, 1e4),          # rad (unwrapped yaw may grow over many turns)
    "vx": (-100.0, 100.0),       # m/s
    "vy": (-100.0, 100.0),       # m/s
    "yaw_rate": (-10.0, 10.0),   # rad/s
    "ax": (-200.0, 200.0),       # m/s²
    "ay": (-200.0, 200.0),       # m/s²
    "sideslip": (-math.pi, math.pi),       # rad
    "steer_front": (-math.pi / 2, math.pi / 2),  # rad
    "steer_rear": (-math.pi / 2, math.pi / 2),   # rad
    "wheel_speed": (-1e4, 1e4),  # rad/s
    "wheel_torque": (-1e5, 1e5), # N·m
    "fx": (-1e6, 1e6),           # N
    "fy": (-1e6, 1e6),           # N
    "fz": (-1e3, 1e6),           # N (slightly negative: a wheel just off the ground)
    "mu": (0.0, 5.0),            # 1
}
#: Physical ranges (inclusive) of command fields, SI: a finite command beyond them (1e300 N·m)
#: is a unit error or a fault, rejected as NaN is, never clipped into a plausible one.
COMMAND_LIMITS: dict[str, tuple[float, float]] = {
    "delta_front": (-math.pi / 2, math.pi / 2),   # rad
    "delta_rear": (-math.pi / 2, math.pi / 2),    # rad
    "yaw_moment": (-1e6, 1e6),                    # N·m
    "torque": (-1e5, 1e5),                        # N·m per wheel
}
#: Reference trajectory ranges: position (m), curvature (1/m), speed (m/s).
REF_POSITION_MAX_M = 1e6
REF_CURVATURE_MAX = 10.0
REF_SPEED_MAX_MPS = 100.0
#: Shortest distance (m) between consecutive reference points: a path has a direction there.
REF_MIN_SEGMENT_M = 1e-9


def implausible_fields(msg: Any, names: Iterable[str],
                       limits: dict[str, tuple[float, float]] = STATE_LIMITS) -> list[str]:
    """``["vx=1.7e+308 (range -100..100)", ...]`` for the listed fields of ``msg`` (scalars
    or arrays) that are not finite or lie outside their range; empty if all are plausible."""
    bad = []
    for k in names:
        raw = getattr(msg, k)
        lo, hi = limits.get(k, (-math.inf, math.inf))
        if isinstance(raw, float | int):  # the per-step scalars, without numpy's overhead
            if not (math.isfinite(raw) and lo <= raw <= hi):
                bad.append(f"{k}={float(raw):.6g} (range {lo:g}..{hi:g})")
            continue
        v = np.asarray(raw, dtype=float)
        ok = np.isfinite(v) & (v >= lo) & (v <= hi)
        if not np.all(ok):
            worst = v.reshape(-1)[int(np.argmin(ok.reshape(-1)))]
            bad.append(f"{k}={worst:.6g} (range {lo:g}..{hi:g})")
    return bad


def check_reference(x, y, yaw, curvature, speed) -> None:
    """Raise ``ValueError`` naming the first non-finite or absurd reference array."""
    arrays = {"x": x, "y": y, "yaw": yaw, "curvature": curvature, "speed": speed}
    n = None
    for name, a in arrays.items():
        a = np.asarray(a, dtype=float)
        if a.ndim != 1 or a.size < 2:
            raise ValueError(f"reference {name}: need a 1-D array of >= 2 samples, got shape "
                             f"{a.shape}")
        if n is not None and a.size != n:
            raise ValueError(f"reference {name}: {a.size} samples, x has {n}")
        n = a.size
        if not np.all(np.isfinite(a)):
            raise ValueError(f"reference {name}: holds non-finite values")
    for name, lim in (("x", REF_POSITION_MAX_M), ("y", REF_POSITION_MAX_M),
                      ("yaw", STATE_LIMITS["yaw"][1]), ("curvature", REF_CURVATURE_MAX)):
        m = float(np.max(np.abs(np.asarray(arrays[name], dtype=float))))
        if m > lim:
            raise ValueError(f"reference {name}: |{name}| up to {m:.3g}, beyond {lim:g}")
    sp = np.asarray(speed, dtype=float)
    if np.any(sp < 0.0) or np.any(sp > REF_SPEED_MAX_MPS):
        raise ValueError(f"reference speed: outside 0..{REF_SPEED_MAX_MPS:g} m/s "
                         f"({sp.min():.3g}..{sp.max():.3g})")
    seg = np.hypot(np.diff(np.asarray(x, dtype=float)), np.diff(np.asarray(y, dtype=float)))
    if np.any(seg <= REF_MIN_SEGMENT_M):
        raise ValueError("reference x, y: consecutive points must be distinct")


class Stamp(Enum):
    """Verdict of :meth:`StampGate.check`."""

    NEW = "new"            # later than the last, within the jump limit: process it
    REPEAT = "repeat"      # equal to the last: answer again from cache
    PAST = "past"          # earlier than the last: rejected
    FUTURE = "future"      # too far ahead of the last: rejected
    JUMPED = "jumped"      # a confirmed jump (new timeline): accept, reset state first


class StampGate:
    """Forward-only stamps with a bounded step; see the module docstring.

    ``quiet_ns`` > 0 (with the arrival times given to :meth:`check`): a jump is confirmed
    only once the current timeline has been silent that long, so a stray source, however
    many messages it sends, never moves a run off a timeline that is still alive (the
    plant republishes its state every 0.25 s even while it waits); a restarted plant's
    timeline is taken once the old one has stopped. A jump ahead is confirmed at once
    within ``quiet_ns`` of the timeline's return from a silence of ``quiet_ns`` (a stalled
    node: its first states after the stall are old ones)."""

    def __init__(self, max_jump_ns: int, quiet_ns: int = 0) -> None:
        if max_jump_ns <= 0:
            raise ValueError(f"max_jump_ns: must be > 0, got {max_jump_ns}")
        self.max_jump_ns = int(max_jump_ns)
        self.quiet_ns = int(quiet_ns)
        self.last_ns: int | None = None
        self._pending_ns: int | None = None
        self._seen_ns: int | None = None
        self._resumed_ns: int | None = None  # when the timeline came back from a silence

    def reset(self) -> None:
        self.last_ns = None
        self._pending_ns = None
        self._seen_ns = None
        self._resumed_ns = None

    def _arrived(self, now_ns: int | None) -> None:
        """A state of the current timeline arrived at ``now_ns``."""
        if (self.quiet_ns > 0 and now_ns is not None and self._seen_ns is not None
                and now_ns - self._seen_ns >= self.quiet_ns):
            self._resumed_ns = now_ns
        self._seen_ns = now_ns

    @property
    def pending_ns(self) -> int | None:
        """The last rejected jump, waiting for a stamp to confirm it (None: none)."""
        return self._pending_ns

    def check(self, stamp_ns: int, now_ns: int | None = None) -> Stamp:
        """Classify ``stamp_ns`` arriving at ``now_ns`` (any monotonic clock; None: no
        quiet rule); NEW and JUMPED make it the new last stamp."""
        last = self.last_ns
        if last is None:
            self.last_ns, self._pending_ns, self._seen_ns = stamp_ns, None, now_ns
            return Stamp.NEW
        if stamp_ns == last:
            self._arrived(now_ns)
            return Stamp.REPEAT
        if 0 < stamp_ns - last <= self.max_jump_ns:
            self.last_ns, self._pending_ns = stamp_ns, None
            self._arrived(now_ns)
            return Stamp.NEW
        pending = self._pending_ns
        alive = (self.quiet_ns > 0 and now_ns is not None and self._seen_ns is not None
                 and now_ns - self._seen_ns < self.quiet_ns)
        if (alive and stamp_ns > last and self._resumed_ns is not None
                and now_ns - self._resumed_ns < self.quiet_ns):
            alive = False  # just back from a silence: its states are old, not proof of life
        if pending is not None and 0 <= stamp_ns - pending <= self.max_jump_ns and not alive:
            self.last_ns, self._pending_ns = stamp_ns, None
            self._seen_ns, self._resumed_ns = now_ns, None
            return Stamp.JUMPED
        self._pending_ns = stamp_ns
        return Stamp.PAST if stamp_ns < last else Stamp.FUTURE


#: Largest forward step between consecutive input stamps that a node accepts without
#: confirmation (ns): 1 s, 100 periods of the 100 Hz graph.
MAX_STAMP_JUMP_NS = 1_000_000_000
#: How long (ns, steady clock) the current timeline must be silent before a node takes a
#: confirmed jump as a new timeline: 4 of the plant's 0.25 s republish periods.
TIMELINE_QUIET_NS = 1_000_000_000


@dataclass(frozen=True)
class InputConfig:
    """Node-level input parameters of the controllers (not of their cores)."""

    sync: str = param("lockstep", "lockstep: answer every state as it arrives; latest: keep "
                      "only the newest state and answer it from a 1 ms steady timer, so a node "
                      "that fell behind (realtime) skips the backlog",
                      choices=("lockstep", "latest"))
    wait_for_subscribers: int = param(
        0, "lockstep: answer the first state of a run only once the node's per-step output "
        "publishers have matched this many subscriptions in total (fourws run sets the "
        "graph's count, the recorder included, so no subscriber misses step 0; the plant "
        "asks again every republish period); 0: answer at once", lo=0, hi=100)


def state_mu(mu: Any) -> float | None:
    """The road adhesion a state's per-wheel ``mu`` gives the MPC: their mean when it is
    finite and positive, else None (no adhesion measured: the MPC takes its ``mu_default``)."""
    values = np.asarray(mu, dtype=float)
    if not values.size:
        return None
    m = float(values.sum()) / values.size          # np.mean's sum and division, less dispatch
    return m if math.isfinite(m) and m > 0.0 else None
