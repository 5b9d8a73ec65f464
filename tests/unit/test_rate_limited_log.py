"""RateLimitedLog: counts every call, logs at most once per period, and two instances with
different severities can share a logger (rclpy refuses one call site at two severities)."""

from __future__ import annotations

import pytest

pytest.importorskip("rclpy")
from rclpy.logging import get_logger  # noqa: E402

from fourws_common.conversions import RateLimitedLog  # noqa: E402


def test_two_severities_on_one_logger_and_the_rate_limit():
    lg = get_logger("fourws_test_rate_limited_log")
    info, warn, err = (RateLimitedLog(lg.info), RateLimitedLog(lg.warning),
                       RateLimitedLog(lg.error))
    for k in range(5):
        info(k * 10**8, "waiting")   # every 0.1 s of the caller's clock
        warn(k * 10**8, "rejected")
        err(k * 10**8, "raised")
    assert (info.count, warn.count, err.count) == (5, 5, 5)
    logged = []
    rl = RateLimitedLog(logged.append, period_s=1.0)
    for k in range(25):
        rl(k * 10**8, "x")
    assert len(logged) == 3 and logged[-1] == "x (rejected 21 so far)"
