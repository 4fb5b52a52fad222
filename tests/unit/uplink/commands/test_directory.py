"""Robot -> site from registration events."""

from __future__ import annotations

from typing import Any

import pytest

from fleetlink.uplink.commands.directory import RobotDirectory

Event = tuple[str | None, dict[str, Any] | None]


def reg(robot: str, site: str, event: str = "registered") -> Event:
    return robot, {"robot": robot, "site": site, "event": event, "robot_type": "tb4"}


@pytest.mark.parametrize(
    ("events", "sites", "registered"),
    [
        ([reg("tb4_01", "a")], {"tb4_01": "a"}, ["tb4_01"]),
        (
            [reg("tb4_01", "a"), reg("tb4_01", "a", "deregistered"), reg("tb4_01", "b")],
            {"tb4_01": "b"},
            ["tb4_01"],
        ),
        ([reg("tb4_01", "a"), reg("tb4_01", "a", "deregistered")], {"tb4_01": "a"}, []),  # last known site
        ([reg("tb4_01", "a"), ("tb4_01", None)], {"tb4_01": None}, []),  # tombstone forgets
        ([("tb4_02", {"site": "a"})], {"tb4_02": "a"}, ["tb4_02"]),  # robot from the key, event defaults
        (
            [reg("tb4_01", "a"), reg("tb4_02", "b"), reg("tb4_03", "a", "deregistered")],
            {"tb4_01": "a", "tb4_02": "b", "tb4_03": "a"},
            ["tb4_01", "tb4_02"],
        ),
    ],
)
def test_directory(events: list[Event], sites: dict[str, str | None], registered: list[str]) -> None:
    directory = RobotDirectory()
    for key, value in events:
        assert directory.apply(key, value)
    assert {robot: directory.site_of(robot) for robot in sites} == sites
    assert directory.registered() == registered


@pytest.mark.parametrize(
    ("key", "value"),
    [
        (None, None),
        (None, {"site": "a"}),
        ("r", {"robot": "r"}),
        ("r", {"robot": "r", "site": ""}),
        ("r", {"robot": "r", "site": 5}),
        ("r", {"robot": "r", "site": "a", "event": "moved"}),
    ],
)
def test_unusable_events_are_ignored(key: str | None, value: dict[str, Any] | None) -> None:
    directory = RobotDirectory()
    assert not directory.apply(key, value)
    assert (len(directory), directory.ignored, directory.sites()) == (0, 1, [])


def test_a_record_from_a_site_that_does_not_hold_the_robot_is_ignored() -> None:
    directory = RobotDirectory(release_after_ms=1000)
    assert directory.apply(*reg("tb4_01", "a"), timestamp_ms=0)
    assert not directory.apply(*reg("tb4_01", "b"), timestamp_ms=10)  # registered at a
    assert not directory.apply(*reg("tb4_01", "b", "deregistered"), timestamp_ms=20)
    assert directory.apply(*reg("tb4_01", "a", "deregistered"), timestamp_ms=100)
    assert not directory.apply(*reg("tb4_01", "b"), timestamp_ms=500)  # a holds it 1 s more
    assert (directory.site_of("tb4_01"), directory.conflicts) == ("a", 3)
    assert directory.apply(*reg("tb4_01", "b"), timestamp_ms=1100)
    assert directory.site_of("tb4_01") == "b"
    assert directory.apply("tb4_01", None)  # an operator's release
    assert directory.apply(*reg("tb4_01", "c"), timestamp_ms=1200)


def test_claims_are_checked_and_applied_at_once() -> None:
    directory = RobotDirectory()
    assert directory.claim("tb4_01", "a", registered=True, now_ms=0) is None
    assert directory.claim("tb4_01", "b", registered=True, now_ms=1) == "the robot is registered at site 'a'"
    assert directory.claim("tb4_01", "a", registered=False, now_ms=2) is None
    assert directory.claim("tb4_01", "b", registered=True, now_ms=3) is None
    owner = directory.owner("tb4_01")
    assert owner is not None
    assert (owner.site, owner.registered, owner.since_ms) == ("b", True, 3)
