"""fleetlink.edge.admin.space: Zenoh admin keys -> operations, replies on concrete keys; run on a service."""

from __future__ import annotations

import json
from typing import Any

import pytest

from fleetlink.edge.admin.space import Target, envelope, execute, parse_body, targets
from tests.unit.edge.admin.world import world

P = "fleetlink/warehouse-a/admin"
NAMES = {"mappings": ["battery", "ir"], "robot_types": ["tb4"]}


def plan(key: str, op: str | None = None, payload: bool = False) -> list[Target]:
    return targets("warehouse-a", key, op, payload, lambda resource: NAMES[resource])


@pytest.mark.parametrize(
    ("key", "op", "payload", "expected"),
    [
        (f"{P}/mappings", None, False, [(f"{P}/mappings", "mappings", None, "get")]),
        (f"{P}/mappings", None, True, [(f"{P}/mappings", "mappings", None, "add")]),
        (f"{P}/mappings", "add", True, [(f"{P}/mappings", "mappings", None, "add")]),
        (f"{P}/mappings/ir", None, False, [(f"{P}/mappings/ir", "mappings", "ir", "get")]),
        (f"{P}/mappings/ir", None, True, [(f"{P}/mappings/ir", "mappings", "ir", "put")]),
        (f"{P}/mappings/ir", "delete", False, [(f"{P}/mappings/ir", "mappings", "ir", "delete")]),
        (f"{P}/robot_types/kb", "put", True, [(f"{P}/robot_types/kb", "robot_types", "kb", "put")]),
        (f"{P}/dry-run", None, True, [(f"{P}/dry-run", "dry-run", None, "dry-run")]),
        (f"{P}/health", None, False, [(f"{P}/health", "health", None, "get")]),
        # wildcards: every concrete key of the site the query intersects, each answered on its own key
        ("fleetlink/*/admin/health", None, False, [(f"{P}/health", "health", None, "get")]),
        (
            f"{P}/mappings/*",
            None,
            False,
            [
                (f"{P}/mappings/battery", "mappings", "battery", "get"),
                (f"{P}/mappings/ir", "mappings", "ir", "get"),
            ],
        ),
        (
            "fleetlink/warehouse-a/admin/r$*",
            None,
            False,
            [(f"{P}/robots", "robots", None, "get"), (f"{P}/robot_types", "robot_types", None, "get")],
        ),
        ("fleetlink/other-site/admin/**", None, False, []),
    ],
)
def test_targets(
    key: str, op: str | None, payload: bool, expected: list[tuple[str, str, str | None, str]]
) -> None:
    got = plan(key, op, payload)
    assert [(t.key, t.resource, t.name, t.op) for t in got] == expected
    assert all(t.status is None for t in got)


def test_a_wildcard_get_of_everything_lists_each_key_once() -> None:
    keys = [t.key for t in plan("fleetlink/**")]
    assert len(keys) == len(set(keys)) == 6 + 3
    assert all("*" not in k for k in keys)


@pytest.mark.parametrize(
    ("key", "op", "payload", "status", "reply_key"),
    [
        (f"{P}/nothing", None, False, 404, f"{P}/nothing"),
        (f"{P}/mappings/a/b", None, False, 404, f"{P}/mappings/a/b"),
        (f"{P}/robots", "delete", False, 405, f"{P}/robots"),
        (f"{P}/mappings", "put", True, 405, f"{P}/mappings"),
        (f"{P}/mappings", "add", False, 400, f"{P}/mappings"),
        (f"{P}/mappings/ir", "explode", False, 400, f"{P}/mappings/ir"),
        # a change through a wildcard is refused, on a concrete key
        (f"{P}/mappings/*", "delete", False, 400, f"{P}/mappings/battery"),
        ("fleetlink/*/admin/mappings", None, True, 400, f"{P}/mappings"),
    ],
)
def test_refused_targets(key: str, op: str | None, payload: bool, status: int, reply_key: str) -> None:
    (target,) = plan(key, op, payload)
    assert (target.status, target.key) == (status, reply_key)
    assert target.error


def run(service_world: Any, key: str, op: str | None = None, body: Any = None) -> list[tuple[int, Any]]:
    service = service_world.service

    def names(resource: str) -> list[str]:
        return (
            [m.name for m in service.mappings()]
            if resource == "mappings"
            else list(service.config.robot_types)
        )

    found = targets("warehouse-a", key, op, body is not None, names)
    return [execute(service, t, body) for t in found]


def test_execute_reads_and_changes() -> None:
    w = world()
    [(status, part)] = run(w, f"{P}/mappings")
    assert status == 200
    assert [m["name"] for m in part["body"]] == ["battery", "ir", "odom_1s"]
    assert part["body"][0]["from"] == "/{robot}/battery_state"
    [(status, part)] = run(
        w, f"{P}/mappings", body={"name": "imu", "from": "/{robot}/imu", "to": "fleet.imu"}
    )
    assert (status, part["body"]["status"]) == (201, "created")
    assert [b.name for b in w.table.match("/kb_01/imu")] == ["imu"]
    [(status, part)] = run(w, f"{P}/mappings/imu", body={"from": "/{robot}/imu", "to": "fleet.imu2"})
    assert (status, part["body"]["status"]) == (200, "changed")
    [(status, part)] = run(w, f"{P}/mappings/imu", "delete")
    assert (status, part["body"]["status"]) == (200, "removed")
    [(status, part)] = run(w, f"{P}/robot_types/kb", body={"match": "/kb_*"})
    assert status == 201
    [(status, part)] = run(w, f"{P}/robot_types/kb")
    assert part["body"]["match"] == "/kb_*"
    [(status, part)] = run(w, f"{P}/dry-run", body={"from": "/{robot}/imu", "to": "x"})
    assert [m["topic"] for m in part["body"]["matches"]] == ["/kb_01/imu", "/tb4_01/imu", "/tb4_02/imu"]
    health = run(w, "fleetlink/*/admin/health")
    assert health == [(200, {"body": w.service.health().as_dict()})]


@pytest.mark.parametrize(
    ("key", "op", "body", "status", "paths"),
    [
        (f"{P}/mappings", None, {"name": "x", "from": "/{robot}/x", "to": "a b"}, 422, ["to"]),
        (f"{P}/mappings", None, {"name": "ir", "from": "/{robot}/x", "to": "t"}, 409, []),
        (f"{P}/mappings/nope", "delete", None, 404, []),
        (f"{P}/robot_types/nope", None, None, 404, []),
        (f"{P}/mappings/ir", None, [], 422, ["<root>"]),
    ],
)
def test_execute_errors(key: str, op: str | None, body: Any, status: int, paths: list[str]) -> None:
    w = world()
    [(got, part)] = run(w, key, op, body)
    assert got == status
    assert part["error"]
    assert [p["path"] for p in part["problems"]] == paths


def test_envelope_and_payloads() -> None:
    data = json.loads(envelope(422, {"error": "e", "problems": []}, site="s", edge_id="e1"))
    assert data == {"status": 422, "site": "s", "edge_id": "e1", "error": "e", "problems": []}
    assert parse_body(None) == (None, None)
    assert parse_body(b"") == (None, None)
    assert parse_body(b'{"a": 1}') == ({"a": 1}, None)
    body, problem = parse_body(b"{nope")
    assert body is None
    assert problem is not None
    assert problem.startswith("the payload is not JSON")
