"""One fault, a bounded number of log lines."""

from __future__ import annotations

import logging

import pytest

from fleetlink.common.ratelimit import LogLimiter


def test_repeats_are_suppressed_then_counted(caplog: pytest.LogCaptureFixture) -> None:
    now = [0.0]
    limiter = LogLimiter(logging.getLogger("t"), interval_s=10, clock=lambda: now[0])
    with caplog.at_level(logging.WARNING):
        emitted = [limiter.log(logging.WARNING, "down", "broker down") for _ in range(1000)]
        now[0] = 11.0
        limiter.log(logging.WARNING, "down", "broker down")
        limiter.log(logging.WARNING, "other", "another problem")
    assert emitted.count(True) == 1
    assert [r.getMessage() for r in caplog.records] == [
        "broker down",
        "broker down (and 999 more like it since the last report)",
        "another problem",
    ]
