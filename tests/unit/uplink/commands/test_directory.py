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
        ([reg("tb4_01", "a"), reg("tb4_01", "b")], {"tb4_01": "b"}, ["tb4_01"]),  # moved
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
