"""fleetlink.edge.admin.changes: every change validated as a whole, errors with body-relative YAML paths."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from fleetlink.edge.admin import changes
from fleetlink.edge.admin.errors import (
    AdminError,
    ConflictError,
    InvalidChangeError,
    NotFoundError,
    OverlayError,
)
from fleetlink.edge.admin.overlay import Overlay, config_data
from tests.unit.edge.admin.world import base_config

BASE = config_data(base_config())
IMU = {"name": "imu", "from": "/{robot}/imu", "to": "fleet.imu"}

Change = Callable[[dict[str, Any], Overlay], changes.Proposal]


def add(body: Any) -> Change:
    return lambda base, overlay: changes.add_mapping(base, overlay, body)


def put(name: str, body: Any) -> Change:
    return lambda base, overlay: changes.change_mapping(base, overlay, name, body)


def put_type(name: str, body: Any) -> Change:
    return lambda base, overlay: changes.put_robot_type(base, overlay, name, body)


INVALID: list[tuple[str, Change, list[tuple[str, str, str | None]]]] = [
    (
        "stage option out of range",
        add({**IMU, "stages": [{"type": "throttle", "hz": 5}, {"type": "throttle", "hz": 0}]}),
        [("stages[1].hz", "greater than 0", "mappings[1].stages[1].hz")],
    ),
    (
        "stage option in a robot type",
        add({**IMU, "robot_type": "tb4", "stages": [{"type": "throttle", "hz": -2}]}),
        [("stages[0].hz", "greater than 0", "robot_types.tb4.mappings[2].stages[0].hz")],
    ),
    (
        "aggregate hop longer than the window",
        add(
            {
                **IMU,
                "stages": [
                    {"type": "aggregate", "window": "1s", "hop": "2s", "fields": ["a"], "ops": ["mean"]}
                ],
            }
        ),
        [("stages[0]", "hop must be", "mappings[1].stages[0]")],
    ),
    (
        "unknown stage type",
        add({**IMU, "stages": [{"type": "median"}]}),
        [("stages[0]", "does not match any of the expected tags", "mappings[1].stages[0]")],
    ),
    (
        "filter expression",
        add({**IMU, "stages": [{"type": "filter", "expr": "linear.x >"}]}),
        [("stages[0].expr", "invalid filter expression", "mappings[1].stages[0].expr")],
    ),
    (
        "duplicate stage names",
        add(
            {
                **IMU,
                "stages": [
                    {"type": "throttle", "hz": 1, "name": "t"},
                    {"type": "throttle", "hz": 2, "name": "t"},
                ],
            }
        ),
        [("stages", "stage names must be unique", "mappings[1].stages")],
    ),
    ("unknown key", add({**IMU, "topic": "x"}), [("topic", "unknown key", "mappings[1].topic")]),
    (
        "missing key",
        add({"name": "imu", "from": "/{robot}/imu"}),
        [("to", "Field required", "mappings[1].to")],
    ),
    ("illegal Kafka topic", add({**IMU, "to": "fleet imu"}), [("to", "Kafka topic", "mappings[1].to")]),
    (
        "capture the pattern lacks",
        add({**IMU, "to": "fleet.{sensor}"}),
        [("to", "{sensor}", "mappings[1].to")],
    ),
    (
        "robot type mapping without {robot}",
        add({**IMU, "from": "/imu", "key": "k", "robot_type": "tb4"}),
        [("from", "capture the robot", "robot_types.tb4.mappings[2].from")],
    ),
    ("bad ROS type", add({**IMU, "type": "Imu"}), [("type", "package/msg/Type", "mappings[1].type")]),
    (
        "unknown robot type",
        add({**IMU, "robot_type": "ghost"}),
        [("robot_type", "unknown robot type 'ghost'", None)],
    ),
    ("body not an object", add(["imu"]), [("<root>", "expected an object", None)]),
    ("no name", add({"from": "/{robot}/imu", "to": "x"}), [("name", "a mapping name", None)]),
    ("rename through PUT", put("ir", {**IMU, "robot_type": "tb4"}), [("name", "cannot be renamed", None)]),
    (
        "robot type glob",
        put_type("kobuki", {"match": "kb 01"}),
        [("match", "namespace glob", "robot_types.kobuki.match")],
    ),
    (
        "robot type mapping",
        put_type("kobuki", {"match": "/kb_*", "mappings": [{**IMU, "to": "a b"}]}),
        [("mappings[0].to", "Kafka topic", "robot_types.kobuki.mappings[0].to")],
    ),
    (
        "robot type mapping name used elsewhere",
        put_type("kobuki", {"match": "/kb_*", "mappings": [{**IMU, "name": "battery"}]}),
        [("mappings[0].name", "already by mappings[0]", None)],
    ),
    ("robot type without match", put_type("kobuki", {"mappings": []}), [("match", "required", None)]),
    ("robot type unknown key", put_type("kobuki", {"match": "/kb_*", "x": 1}), [("x", "unknown key", None)]),
]


@pytest.mark.parametrize(("what", "change", "problems"), INVALID, ids=[c[0] for c in INVALID])
def test_invalid_changes_name_the_field(
    what: str, change: Change, problems: list[tuple[str, str, str | None]]
) -> None:
    with pytest.raises(InvalidChangeError) as caught:
        change(BASE, Overlay())
    got = caught.value.problems
    assert caught.value.status == 422
    assert [p.path for p in got] == [p[0] for p in problems], what
    for problem, (_, fragment, config_path) in zip(got, problems, strict=True):
        assert fragment in problem.message
        assert problem.config_path == config_path


@pytest.mark.parametrize(
    ("change", "error", "status"),
    [
        (add({**IMU, "name": "ir"}), ConflictError, 409),
        (put("nope", IMU), NotFoundError, 404),
        (lambda b, o: changes.remove_mapping(b, o, "nope"), NotFoundError, 404),
        (lambda b, o: changes.remove_robot_type(b, o, "nope"), NotFoundError, 404),
    ],
)
def test_refusals(change: Change, error: type[AdminError], status: int) -> None:
    with pytest.raises(error) as caught:
        change(BASE, Overlay())
    assert caught.value.status == status


def test_add_change_remove_a_site_mapping() -> None:
    added = changes.add_mapping(BASE, Overlay(), IMU)
    assert added.created
    assert [m.name for m in added.config.mappings] == ["battery", "imu"]
    changed = changes.change_mapping(BASE, added.overlay, "imu", {**IMU, "to": "fleet.imu2"})
    assert changed.config.mappings[1].to == "fleet.imu2"
    assert changed.overlay.mapping("imu") == {**IMU, "to": "fleet.imu2"}
    removed = changes.remove_mapping(BASE, changed.overlay, "imu")
    assert removed.overlay.empty  # an admin-added mapping leaves no trace when removed
    assert [m.name for m in removed.config.mappings] == ["battery"]


def test_removing_a_config_file_mapping_is_remembered() -> None:
    removed = changes.remove_mapping(BASE, Overlay(), "ir")
    assert removed.overlay.removed_mappings == ["ir"]
    assert [m.name for m in removed.config.robot_types["tb4"].mappings] == ["odom_1s"]
    back = changes.add_mapping(
        BASE, removed.overlay, {"name": "ir", "robot_type": "tb4", "from": "/{robot}/ir", "to": "fleet.ir"}
    )
    assert [m.name for m in back.config.robot_types["tb4"].mappings] == ["odom_1s", "ir"]


def test_robot_type_create_change_with_mappings_and_remove() -> None:
    created = changes.put_robot_type(BASE, Overlay(), "kobuki", {"match": "/kb_*", "mappings": [IMU]})
    assert created.created
    assert [m.name for m in created.config.robot_types["kobuki"].mappings] == ["imu"]
    # the mapping list is complete: ir leaves tb4, a new one arrives
    changed = changes.put_robot_type(
        BASE,
        created.overlay,
        "tb4",
        {
            "match": "/tb4_*",
            "mappings": [
                {"name": "odom_1s", "from": "/{robot}/odom", "to": "fleet.odom"},
                {"name": "hazards", "from": "/{robot}/hazard_detection", "to": "fleet.hazards"},
            ],
        },
    )
    assert not changed.created
    assert [m.name for m in changed.config.robot_types["tb4"].mappings] == ["odom_1s", "hazards"]
    assert changed.overlay.removed_mappings == ["ir"]
    match_only = changes.put_robot_type(BASE, changed.overlay, "tb4", {"match": "/turtle_*"})
    assert [m.name for m in match_only.config.robot_types["tb4"].mappings] == ["odom_1s", "hazards"]
    assert match_only.config.robot_types["tb4"].match == "/turtle_*"
    gone = changes.remove_robot_type(BASE, match_only.overlay, "kobuki")
    assert "kobuki" not in gone.config.robot_types
    assert gone.overlay.mapping("imu") is None
    assert gone.overlay.removed_robot_types == []  # it never was in the config file
    gone_too = changes.remove_robot_type(BASE, gone.overlay, "tb4")
    assert gone_too.overlay.removed_robot_types == ["tb4"]
    assert gone_too.config.robot_types == {}


def test_candidate_for_a_dry_run_changes_nothing() -> None:
    overlay = Overlay()
    config, name = changes.candidate_mapping(BASE, overlay, {**IMU, "robot_type": "tb4"})
    assert name == "imu"
    assert [m.name for m in config.robot_types["tb4"].mappings] == ["ir", "odom_1s", "imu"]
    assert overlay.empty


def test_effective_config_at_start() -> None:
    overlay = changes.add_mapping(BASE, Overlay(), {**IMU, "robot_type": "tb4"}).overlay
    assert [m.name for m in changes.effective(BASE, overlay).robot_types["tb4"].mappings][-1] == "imu"


@pytest.mark.parametrize(
    ("base_change", "message"),
    [
        # the config file lost the robot type the saved mapping belongs to
        (lambda data: data["robot_types"].pop("tb4"), "'imu': its robot type no longer exists"),
        # the config file now makes the saved mapping invalid (its capture is no longer the robot)
        (lambda data: data.update(edge_id="bad/id"), "edge_id"),
    ],
)
def test_effective_config_refuses_an_overlay_that_no_longer_fits(
    base_change: Callable[[dict[str, Any]], object], message: str
) -> None:
    overlay = changes.add_mapping(BASE, Overlay(), {**IMU, "robot_type": "tb4"}).overlay
    data = config_data(base_config())
    base_change(data)
    with pytest.raises(OverlayError, match=message) as caught:
        changes.effective(data, overlay, source="/x/admin-overlay.yaml")
    assert "/x/admin-overlay.yaml" in str(caught.value)
