"""fleetlink.edge.admin.overlay: the overlay laid over the config file's data, in a fixed order."""

from __future__ import annotations

from typing import Any

import pytest
from pydantic import ValidationError

from fleetlink.edge.admin.overlay import Overlay, RobotTypeOverlay, apply_overlay, locate_mapping, owner_of
from tests.unit.edge.admin.world import base_data

IMU = {"name": "imu", "from": "/{robot}/imu", "to": "fleet.imu"}


def names(data: dict[str, Any]) -> dict[str, list[str]]:
    out = {"<site>": [m["name"] for m in data["mappings"]]}
    out.update({t: [m["name"] for m in rt["mappings"]] for t, rt in data["robot_types"].items()})
    return out


@pytest.mark.parametrize(
    ("overlay", "expected"),
    [
        (Overlay(), {"<site>": ["battery"], "tb4": ["ir", "odom_1s"]}),
        # added: appended to the owner's list
        (Overlay(mappings=[IMU]), {"<site>": ["battery", "imu"], "tb4": ["ir", "odom_1s"]}),
        (
            Overlay(mappings=[{**IMU, "robot_type": "tb4"}]),
            {"<site>": ["battery"], "tb4": ["ir", "odom_1s", "imu"]},
        ),
        # changed with the same owner: keeps its place
        (
            Overlay(mappings=[{"name": "ir", "robot_type": "tb4", "from": "/{robot}/ir", "to": "fleet.ir2"}]),
            {"<site>": ["battery"], "tb4": ["ir", "odom_1s"]},
        ),
        # changed to another owner: moves, appended there
        (
            Overlay(mappings=[{"name": "ir", "from": "/{robot}/ir", "to": "fleet.ir2"}]),
            {"<site>": ["battery", "ir"], "tb4": ["odom_1s"]},
        ),
        (Overlay(removed_mappings=["ir", "battery", "not-there"]), {"<site>": [], "tb4": ["odom_1s"]}),
        # a removed type takes its mappings along; one re-created in the same overlay starts empty
        (Overlay(removed_robot_types=["tb4"]), {"<site>": ["battery"]}),
        (
            Overlay(
                removed_robot_types=["tb4"],
                robot_types={"tb4": RobotTypeOverlay(match="/t_*")},
                mappings=[{**IMU, "robot_type": "tb4"}],
            ),
            {"<site>": ["battery"], "tb4": ["imu"]},
        ),
        (
            Overlay(robot_types={"kobuki": RobotTypeOverlay(match="/kb_*")}),
            {"<site>": ["battery"], "tb4": ["ir", "odom_1s"], "kobuki": []},
        ),
        # removed then re-added by name: the overlay entry wins (mappings are applied last)
        (
            Overlay(
                removed_mappings=["battery"],
                mappings=[{"name": "battery", "from": "/{robot}/bat", "to": "b"}],
            ),
            {"<site>": ["battery"], "tb4": ["ir", "odom_1s"]},
        ),
        # a mapping for a type that does not exist is not placed (changes.effective reports it)
        (
            Overlay(mappings=[{**IMU, "robot_type": "ghost"}]),
            {"<site>": ["battery"], "tb4": ["ir", "odom_1s"]},
        ),
    ],
)
def test_apply_overlay(overlay: Overlay, expected: dict[str, list[str]]) -> None:
    base = base_data()
    before = repr(base)
    assert names(apply_overlay(base, overlay)) == expected
    assert repr(base) == before  # the config file's data is not touched


def test_changed_match_keeps_the_type_mappings() -> None:
    data = apply_overlay(base_data(), Overlay(robot_types={"tb4": RobotTypeOverlay(match="/turtle_*")}))
    assert data["robot_types"]["tb4"]["match"] == "/turtle_*"
    assert [m["name"] for m in data["robot_types"]["tb4"]["mappings"]] == ["ir", "odom_1s"]


def test_changed_mapping_is_the_overlay_body_without_robot_type() -> None:
    body = {"name": "ir", "robot_type": "tb4", "from": "/{robot}/ir", "to": "fleet.ir2"}
    data = apply_overlay(base_data(), Overlay(mappings=[body]))
    assert data["robot_types"]["tb4"]["mappings"][0] == {
        "name": "ir",
        "from": "/{robot}/ir",
        "to": "fleet.ir2",
    }


@pytest.mark.parametrize(
    ("name", "where", "owner"),
    [
        ("battery", ("mappings", 0), None),
        ("odom_1s", ("robot_types", "tb4", "mappings", 1), "tb4"),
        ("nope", None, None),
    ],
)
def test_locate_mapping(name: str, where: tuple[Any, ...] | None, owner: str | None) -> None:
    assert locate_mapping(base_data(), name) == where
    assert owner_of(base_data(), name) == owner


@pytest.mark.parametrize(
    ("mappings", "message"),
    [
        ([{"from": "/a"}], "no mapping name"),
        ([IMU, IMU], "listed twice"),
    ],
)
def test_overlay_entries_are_named_once(mappings: list[dict[str, Any]], message: str) -> None:
    with pytest.raises(ValidationError, match=message):
        Overlay(mappings=mappings)


def test_overlay_edits_are_copies() -> None:
    overlay = Overlay()
    changed = (
        overlay.with_mapping(IMU).without_mapping("battery", removed=True).with_robot_type("kb", "/kb_*")
    )
    assert overlay.empty
    assert changed.mapping("imu") == IMU
    assert changed.removed_mappings == ["battery"]
    dropped = changed.with_mapping({**IMU, "name": "x", "robot_type": "kb"}).without_robot_type(
        "kb", removed=False
    )
    assert [m["name"] for m in dropped.mappings] == ["imu"]
    assert dropped.robot_types == {}
    assert dropped.removed_robot_types == []
