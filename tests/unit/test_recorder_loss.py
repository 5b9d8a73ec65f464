"""The recorder's loss count (recorder_node.StampGaps, lost_counts): the step stamps missing
between the stamps it received, per per-step topic, against DDS's message-lost total.

Oracle: the stamps that were left out of a k × 10 ms sequence, counted by construction.
"""

from __future__ import annotations

import pytest

pytest.importorskip("rclpy")
from fourws_bringup.recorder_node import StampGaps, lost_counts  # noqa: E402

DT_NS = 10_000_000


def received(stamps) -> StampGaps:
    g = StampGaps()
    for k in stamps:
        g.add(k * DT_NS)
    return g


def test_a_long_gap_counts_every_missing_step_not_one_event():
    """The case of the report: DDS said 1 lost while 1965 commands were missing."""
    steps = range(3000)
    cmd = [k for k in steps if not 500 <= k < 2465]
    gaps = {"/vehicle/state": received(steps), "/control/mpc_command": received(cmd)}
    assert lost_counts(gaps, {"/control/mpc_command": 1}) == {"/control/mpc_command": 1965}


def test_several_gaps_repeats_and_the_period_from_another_topic():
    # Lockstep repeats a waiting state (same stamp): no gap. Every other torque is lost, so
    # that topic alone never shows the period; the state's 10 ms gives it.
    state = [0, 1, 1, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11]
    torques = [0, 2, 4, 6, 8, 10]
    odom = [0, 1, 2, 5, 6, 7, 11]
    gaps = {"/vehicle/state": received(state), "/control/wheel_torques": received(torques),
            "/vehicle/odom": received(odom)}
    assert lost_counts(gaps, {}) == {"/control/wheel_torques": 5, "/vehicle/odom": 5}
    assert gaps["/control/wheel_torques"].missing(DT_NS) == 5
    assert lost_counts(gaps, {}, period_ns=2 * DT_NS) == {"/vehicle/odom": 2}


def test_dds_total_counts_when_it_is_larger_and_nothing_lost_is_empty():
    gaps = {"/vehicle/state": received(range(100)), "/clock": received(range(100))}
    assert lost_counts(gaps, {}) == {}
    # Lost after the last stamp received: no gap shows it, DDS's count does.
    assert lost_counts(gaps, {"/clock": 7}) == {"/clock": 7}
    assert lost_counts({}, {}) == {}
    assert lost_counts({"/vehicle/state": received([5])}, {}) == {}


def test_a_stray_is_no_loss_and_a_new_run_counts_afresh():
    """A state stamped 1e6 s ahead (rejected by every node) would have been 1e8 'missing'
    steps; a second run into the same recorder (stamps back at 0) is no gap either; what
    the second run loses is counted."""
    stray = 10**8  # steps: 1e6 s
    run1 = list(range(300))
    run2 = [k for k in range(300) if k not in (100, 101, 102)]
    g = received([*run1[:150], stray, *run1[150:], *run2])
    assert g.missing(DT_NS) == 3
