"""edge.runtime.robot_log: when and how each robot registered, and its recent changes."""

from __future__ import annotations

import pytest

from fleetlink.edge.runtime.registration import RobotChange
from fleetlink.edge.runtime.robot_log import RobotLog

pytestmark = pytest.mark.unit


def change(robot: str, registered: bool, reason: str, at_ms: int) -> RobotChange:
    return RobotChange(robot, "tb4", registered, reason, at_ms)


def test_registration_time_and_kind_per_robot() -> None:
    log = RobotLog()
    log.record(change("tb4_01", True, "discovered", 1_000))
    log.record(change("tb4_02", True, "explicit", 2_000))
    assert log.details() == {
        "tb4_01": {"registered_at_ms": 1_000, "explicit": False, "state": "registered"},
        "tb4_02": {"registered_at_ms": 2_000, "explicit": True, "state": "registered"},
    }


def test_deregistered_robots_leave_the_details_and_keep_their_history() -> None:
    log = RobotLog(max_events=3)
    for i in range(4):
        log.record(change("tb4_01", i % 2 == 0, "discovered" if i % 2 == 0 else "liveliness_lost", i))
    assert "tb4_01" not in log.details()
    history = log.history()["tb4_01"]
    assert [e["at_ms"] for e in history] == [1, 2, 3]  # the last three, oldest first
    assert [e["event"] for e in history] == ["deregistered", "registered", "deregistered"]
    assert history[0]["reason"] == "liveliness_lost"


def test_the_robot_heard_of_longest_ago_is_forgotten_first() -> None:
    log = RobotLog(max_robots=2)
    log.record(change("a", True, "discovered", 1))
    log.record(change("b", True, "discovered", 2))
    log.record(change("c", True, "discovered", 3))
    assert sorted(log.history()) == ["b", "c"]
