"""Input guards shared by the nodes: plausible values, sane references, forward-only stamps."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from fourws_common.input_guard import (
    Stamp,
    StampGate,
    check_reference,
    implausible_fields,
)

MS = 10_000_000  # one 100 Hz step in ns


def _state(**kw):
    base = dict(x=1.0, y=0.5, yaw=0.1, vx=16.0, vy=0.1, yaw_rate=0.05,
                fz=np.full(4, 1800.0), fy=np.zeros(4), mu=np.full(4, 0.5))
    base.update(kw)
    return SimpleNamespace(**base)


def test_finite_extremes_are_as_implausible_as_nan():
    names = ("x", "y", "yaw", "vx", "vy", "yaw_rate", "fz", "mu")
    assert implausible_fields(_state(), names) == []
    for field, value in (("vx", 1.7e308), ("x", 1e300), ("yaw_rate", math.nan),
                         ("vy", -math.inf), ("mu", np.array([0.5, 0.5, 7.0, 0.5])),
                         ("fz", np.array([1.0, 2.0, math.nan, 3.0]))):
        bad = implausible_fields(_state(**{field: value}), names)
        assert len(bad) == 1 and bad[0].startswith(f"{field}="), (field, bad)


def test_a_poisoned_reference_is_refused_naming_the_array():
    x = np.linspace(0.0, 100.0, 101)
    ok = (x, 0.0 * x, 0.0 * x, 0.0 * x, 16.0 + 0.0 * x)
    check_reference(*ok)
    with pytest.raises(ValueError, match="reference x"):
        check_reference(x * 1e298, *ok[1:])
    with pytest.raises(ValueError, match="reference speed"):
        check_reference(*ok[:4], -ok[4])
    with pytest.raises(ValueError, match="curvature"):
        check_reference(*ok[:3], ok[3] + 1e3, ok[4])
    with pytest.raises(ValueError, match="non-finite"):
        check_reference(x, x * np.nan, *ok[2:])


def test_a_reference_with_an_absurd_yaw_or_repeated_points_is_refused():
    x = np.linspace(0.0, 100.0, 101)
    ok = (x, 0.0 * x, 0.0 * x, 0.0 * x, 16.0 + 0.0 * x)
    yaw = ok[2].copy()
    yaw[5] = 1e300
    with pytest.raises(ValueError, match="reference yaw"):
        check_reference(ok[0], ok[1], yaw, *ok[3:])
    with pytest.raises(ValueError, match="distinct"):
        check_reference([0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [10.0, 10.0])


def test_a_stray_future_stamp_is_rejected_and_never_becomes_the_last():
    g = StampGate(100 * MS)
    assert [g.check(k * MS) for k in range(3)] == [Stamp.NEW] * 3
    assert g.check(2 * MS) is Stamp.REPEAT
    assert g.check(10**6 * 10**9) is Stamp.FUTURE          # 1e6 s ahead: a stray
    assert g.last_ns == 2 * MS
    assert [g.check(k * MS) for k in range(3, 6)] == [Stamp.NEW] * 3
    assert g.check(1 * MS) is Stamp.PAST                   # a stray from the past
    assert g.check(6 * MS) is Stamp.NEW and g.last_ns == 6 * MS


def test_a_confirmed_jump_is_a_new_timeline():
    g = StampGate(100 * MS)
    for k in range(500, 510):
        g.check(k * MS)
    assert g.check(0) is Stamp.PAST                        # a restarted plant's step 0 ...
    assert g.check(0) is Stamp.JUMPED                      # ... republished: confirmed
    assert g.check(MS) is Stamp.NEW
    assert g.check(10**12) is Stamp.FUTURE                 # a realtime stall of 1000 s ...
    assert g.check(10**12 + MS) is Stamp.JUMPED            # ... confirmed by the next state
    with pytest.raises(ValueError):
        StampGate(0)


def test_strays_in_a_row_never_move_a_live_timeline_and_a_restart_is_taken_once_it_is_quiet():
    """Issue 41, item 2: two future stamps back to back confirmed each other as a new timeline
    while the plant was still publishing. With arrival times, a jump is taken only once the
    current timeline has been silent for quiet_ns."""
    ms = 1_000_000
    gate = StampGate(1000 * ms, quiet_ns=1000 * ms)
    assert gate.check(0, now_ns=0) is Stamp.NEW
    assert gate.check(10 * ms, now_ns=5 * ms) is Stamp.NEW
    far = 10**6 * 1000 * ms
    assert gate.check(far, now_ns=6 * ms) is Stamp.FUTURE
    assert gate.check(far + 10 * ms, now_ns=7 * ms) is Stamp.FUTURE      # not confirmed
    assert gate.check(20 * ms, now_ns=8 * ms) is Stamp.NEW               # the plant goes on
    assert gate.last_ns == 20 * ms
    # the plant restarts from 0: its republished state 0 is taken once the old timeline has
    # been quiet for 1 s, not before
    assert gate.check(0, now_ns=500 * ms) is Stamp.PAST
    assert gate.check(0, now_ns=750 * ms) is Stamp.PAST
    assert gate.check(0, now_ns=1009 * ms) is Stamp.JUMPED
    assert gate.check(10 * ms, now_ns=1010 * ms) is Stamp.NEW
    # without arrival times the gate confirms at once, as before
    plain = StampGate(1000 * ms)
    plain.check(0)
    plain.check(far)
    assert plain.check(far + 10 * ms) is Stamp.JUMPED


def test_after_a_stall_of_the_node_the_newest_states_are_taken_at_the_first_confirmation():
    """Issue 41, item 5: a node stopped for 2 s first handles a state sent before the stall;
    the plant's newest states, 2 s ahead, must then be confirmed at once, not rejected for
    quiet_ns as strays of a live timeline (the MPC answered 1 s late, the hold lasted 2.5 s).
    A jump back right after the stall still waits for the quiet rule."""
    ms = 1_000_000
    gate = StampGate(1000 * ms, quiet_ns=1000 * ms)
    for k in range(100):                                   # realtime: stamp = arrival
        assert gate.check(k * 10 * ms, now_ns=k * 10 * ms) in (Stamp.NEW,)
    # stopped from 1.0 s to 3.0 s; resumed, it handles the state sent at 1.0 s first
    assert gate.check(100 * 10 * ms, now_ns=3000 * ms) is Stamp.NEW
    assert gate.check(300 * 10 * ms, now_ns=3001 * ms) is Stamp.FUTURE   # 2 s ahead ...
    assert gate.check(301 * 10 * ms, now_ns=3010 * ms) is Stamp.JUMPED   # ... confirmed
    assert gate.check(302 * 10 * ms, now_ns=3020 * ms) is Stamp.NEW
    # strays right after: a pair from the past is not taken while the plant goes on
    assert gate.check(0, now_ns=3021 * ms) is Stamp.PAST
    assert gate.check(10 * ms, now_ns=3022 * ms) is Stamp.PAST
    assert gate.check(303 * 10 * ms, now_ns=3030 * ms) is Stamp.NEW
