"""The admin HTTP API in process (FastAPI TestClient, no sockets): routes, auth, errors, persistence,
the OpenAPI document, and a fuzz run that must find no server error."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from openapi_spec_validator import validate
from prometheus_client.parser import text_string_to_metric_families
from pydantic import SecretStr

from fleetlink.common.login_limiter import LoginLimiter
from fleetlink.common.metrics import PrometheusMetrics
from fleetlink.edge.admin.backend import EdgeSnapshot, MappingCounts
from fleetlink.edge.admin.http import create_app
from fleetlink.edge.admin.store import OverlayStore
from tests.unit.edge.admin.world import IMU, World, world

TOKEN = "tok-" + "x" * 20
AUTH = {"Authorization": f"Bearer {TOKEN}"}
IMU_MAPPING = {"name": "imu", "from": "/{robot}/imu", "to": "fleet.imu", "type": IMU}


def client(w: World, *, token: str | None = TOKEN, limiter: LoginLimiter | None = None) -> TestClient:
    metrics = PrometheusMetrics("edge")
    w.service.telemetry.metrics = metrics
    app = create_app(w.service, token=SecretStr(token) if token else None, metrics=metrics, limiter=limiter)
    return TestClient(app, raise_server_exceptions=False)


@pytest.fixture
def w(tmp_path: Path) -> World:
    return world(tmp_path / "admin-overlay.yaml")


ROUTES = [
    ("get", "/robots"),
    ("get", "/topics"),
    ("get", "/mappings"),
    ("get", "/mappings/ir"),
    ("post", "/mappings"),
    ("put", "/mappings/ir"),
    ("delete", "/mappings/ir"),
    ("post", "/dry-run"),
    ("get", "/robot_types"),
    ("put", "/robot_types/tb4"),
    ("delete", "/robot_types/tb4"),
    ("get", "/overlay"),
    ("get", "/spool/damage"),
    ("post", "/spool/damage/acknowledge"),
]


@pytest.mark.parametrize(("method", "path"), ROUTES)
@pytest.mark.parametrize("header", [None, "Bearer wrong", f"Basic {TOKEN}", "Bearer", TOKEN])
def test_every_admin_route_needs_the_token(w: World, method: str, path: str, header: str | None) -> None:
    headers = {"Authorization": header} if header is not None else {}
    response = client(w).request(method, path, headers=headers, json=IMU_MAPPING)
    assert response.status_code == 401
    assert response.headers["www-authenticate"] == "Bearer"
    assert TOKEN not in response.text
    assert w.backend.installs == 0


@pytest.mark.parametrize("path", ["/health", "/metrics", "/openapi.json"])
def test_probes_and_the_document_are_open(w: World, path: str) -> None:
    assert client(w).get(path).status_code == 200


def test_without_a_token_the_api_is_open(w: World) -> None:
    assert client(w, token=None).get("/mappings").status_code == 200


def test_wrong_tokens_lock_a_client_out(w: World) -> None:
    """200 wrong tokens in a burst: five are checked, the rest are refused unchecked. The clock
    stands still: on a loaded machine 200 requests may outlast the first lockout."""
    c = client(w, limiter=LoginLimiter(clock=lambda: 1000.0))
    answers = [
        c.get("/mappings", headers={"Authorization": f"Bearer guess-{i}"}).status_code for i in range(200)
    ]
    assert answers[:5] == [401] * 5
    assert set(answers[5:]) == {429}
    locked = c.get("/mappings", headers=AUTH)
    assert locked.status_code == 429  # the right token waits out the lockout too
    assert int(locked.headers["retry-after"]) >= 1
    assert c.get("/mappings").status_code == 429
    assert w.backend.installs == 0


def test_mappings_with_live_counters(w: World) -> None:
    w.snapshot[0] = EdgeSnapshot(
        mappings={
            "ir": MappingCounts(
                received=10,
                emitted=4,
                dropped=6,
                stages={"throttle": {"received": 10, "passed": 4, "dropped": 6, "emitted": 4}},
            )
        }
    )
    body = client(w).get("/mappings/ir", headers=AUTH).json()
    assert body["counters"] == {
        "received": 10,
        "emitted": 4,
        "dropped": 6,
        "dead_lettered": 0,
        "type_mismatch": 0,
    }
    assert body["stage_counters"] == [
        {
            "name": "throttle",
            "type": "throttle",
            "received": 10,
            "passed": 4,
            "dropped": 6,
            "late": 0,
            "errors": 0,
            "emitted": 4,
        }
    ]
    assert body["robots"] == ["tb4_01"]
    assert body["from"] == "/{robot}/ir_intensity"
    assert body["origin"] == "config"
    listed = client(w).get("/mappings", headers=AUTH).json()
    assert [m["name"] for m in listed] == ["battery", "ir", "odom_1s"]


def test_add_change_remove_applies_and_persists(w: World, tmp_path: Path) -> None:
    api = client(w)
    created = api.post("/mappings", headers=AUTH, json={**IMU_MAPPING, "robot_type": "tb4"})
    assert created.status_code == 201
    assert created.json() == {
        "status": "created",
        "kind": "mapping",
        "name": "imu",
        "overlay": str(tmp_path / "admin-overlay.yaml"),
    }
    assert [b.name for b in w.table.match("/tb4_01/imu")] == ["imu"]
    assert api.get("/mappings/imu", headers=AUTH).json()["origin"] == "admin"
    saved = OverlayStore(tmp_path / "admin-overlay.yaml").load()
    assert saved.mapping("imu") == {**IMU_MAPPING, "robot_type": "tb4"}

    changed = api.put(
        "/mappings/imu",
        headers=AUTH,
        json={"from": "/{robot}/imu", "to": "fleet.imu.v2", "robot_type": "tb4"},
    )
    assert changed.status_code == 200
    assert [b.kafka_topic for b in w.table.match("/tb4_01/imu")] == ["fleet.imu.v2"]

    removed = api.delete("/mappings/imu", headers=AUTH)
    assert removed.json()["status"] == "removed"
    assert w.table.match("/tb4_01/imu") == ()
    assert OverlayStore(tmp_path / "admin-overlay.yaml").load().empty
    assert w.backend.installs == 3


def test_restart_keeps_the_changes(w: World, tmp_path: Path) -> None:
    api = client(w)
    assert api.delete("/mappings/battery", headers=AUTH).status_code == 200
    assert (
        api.put(
            "/robot_types/kobuki",
            headers=AUTH,
            json={
                "match": "/kb_*",
                "mappings": [{"name": "kb_imu", "from": "/{robot}/imu", "to": "fleet.kb.imu"}],
            },
        ).status_code
        == 201
    )
    again = world(tmp_path / "admin-overlay.yaml")  # a new process: the config file + the saved overlay
    assert [m.name for m in again.service.config.mappings] == []
    assert [m.name for m in again.service.config.robot_types["kobuki"].mappings] == ["kb_imu"]
    types = client(again).get("/robot_types", headers=AUTH).json()
    assert [(t["name"], t["origin"]) for t in types] == [("tb4", "config"), ("kobuki", "admin")]


@pytest.mark.parametrize(
    ("method", "path", "body", "status", "paths"),
    [
        (
            "post",
            "/mappings",
            {**IMU_MAPPING, "stages": [{"type": "throttle", "hz": 0}]},
            422,
            ["stages[0].hz"],
        ),
        (
            "post",
            "/mappings",
            {
                **IMU_MAPPING,
                "stages": [{"type": "aggregate", "window": "1s", "fields": ["a"], "ops": ["median"]}],
            },
            422,
            ["stages[0].ops[0]"],
        ),
        (
            "post",
            "/mappings",
            {**IMU_MAPPING, "robot_type": "tb4", "from": "/imu", "key": "k"},
            422,
            ["from"],
        ),
        ("post", "/mappings", {**IMU_MAPPING, "robot_type": "ghost"}, 422, ["robot_type"]),
        ("post", "/mappings", {**IMU_MAPPING, "extra": 1}, 422, ["extra"]),
        ("post", "/mappings", [1, 2], 422, ["<root>"]),
        ("post", "/mappings", {**IMU_MAPPING, "name": "ir"}, 409, []),
        ("put", "/mappings/nope", IMU_MAPPING, 404, []),
        ("put", "/mappings/ir", {**IMU_MAPPING, "name": "other"}, 422, ["name"]),
        ("put", "/mappings/bad%20name", IMU_MAPPING, 422, ["path.name"]),
        ("delete", "/mappings/nope", None, 404, []),
        ("get", "/mappings/nope", None, 404, []),
        (
            "put",
            "/robot_types/kb",
            {"match": "/kb_*", "mappings": [{"name": "x", "from": "/imu", "to": "t"}]},
            422,
            ["mappings[0].from"],
        ),
        ("delete", "/robot_types/ghost", None, 404, []),
    ],
)
def test_refusals_change_nothing(
    w: World, tmp_path: Path, method: str, path: str, body: Any, status: int, paths: list[str]
) -> None:
    response = client(w).request(method, path, headers=AUTH, json=body)
    assert response.status_code == status, response.text
    error = response.json()
    assert error["status"] == status
    assert error["error"]
    assert [p["path"] for p in error["problems"]] == paths
    assert w.backend.installs == 0
    assert not (tmp_path / "admin-overlay.yaml").exists()


def test_dry_run_against_the_graph(w: World) -> None:
    api = client(w)
    site = api.post("/dry-run", headers=AUTH, json={"from": "/{robot}/imu", "to": "fleet.{robot}.imu"}).json()
    assert [(m["topic"], m["kafka_topic"], m["key"]) for m in site["matches"]] == [
        ("/kb_01/imu", "fleet.kb_01.imu", "kb_01"),
        ("/tb4_01/imu", "fleet.tb4_01.imu", "tb4_01"),
        ("/tb4_02/imu", "fleet.tb4_02.imu", "tb4_02"),
    ]
    typed = api.post(
        "/dry-run",
        headers=AUTH,
        json={
            "name": "x",
            "robot_type": "tb4",
            "from": "/{robot}/imu",
            "to": "fleet.imu",
            "type": "sensor_msgs/msg/Temperature",
        },
    )
    matches = typed.json()["matches"]
    assert [(m["robot"], m["registered"], m["type_ok"]) for m in matches] == [
        ("tb4_01", True, False),
        ("tb4_02", False, False),
    ]
    assert api.post("/dry-run", headers=AUTH, json={"from": "/{robot}/imu", "to": "a b"}).status_code == 422
    assert w.backend.installs == 0
    assert w.table.match("/kb_01/imu") == ()


def test_topics_show_publishers_and_mappings(w: World) -> None:
    topics = {t["topic"]: t for t in client(w).get("/topics", headers=AUTH).json()}
    ir = topics["/tb4_01/ir_intensity"]
    assert ir["publishers"][0]["node"] == "/tb4_01/create3"
    assert [(m["mapping"], m["robot"], m["kafka_topic"]) for m in ir["mappings"]] == [
        ("ir", "tb4_01", "fleet.ir")
    ]
    assert topics["/tb4_02/ir_intensity"]["mappings"] == []  # tb4_02 is not registered
    assert [m["mapping"] for m in topics["/tb4_02/battery_state"]["mappings"]] == ["battery"]


def test_robots(w: World) -> None:
    assert client(w).get("/robots", headers=AUTH).json() == [
        {
            "robot": "tb4_01",
            "robot_type": "tb4",
            "registered_at": None,
            "registered_since": None,
            "state": "registered",
            "explicit": False,
            "history": [],
        }
    ]


def test_metrics_expose_the_counters(w: World) -> None:
    w.snapshot[0] = EdgeSnapshot(mappings={"ir": MappingCounts(received=7, emitted=3, dead_lettered=1)})
    text = client(w).get("/metrics").text
    values = {
        (s.name, tuple(sorted(s.labels.items()))): s.value
        for fam in text_string_to_metric_families(text)
        for s in fam.samples
    }
    assert values[("fleetlink_mapping_received_total", (("mapping", "ir"),))] == 7
    assert values[("fleetlink_mapping_emitted_total", (("mapping", "ir"),))] == 3
    assert values[("fleetlink_robots_registered", ())] == 1
    assert values[("fleetlink_health", (("state", "degraded"),))] == 1  # a dead letter just now
    health = client(w).get("/health").json()
    assert health["degraded_mappings"] == {"ir": ["dead_letters"]}


def test_openapi_document_validates(w: World) -> None:
    document = client(w).get("/openapi.json").json()
    validate(document)
    assert {
        "/robots",
        "/topics",
        "/mappings",
        "/mappings/{name}",
        "/dry-run",
        "/robot_types/{name}",
        "/health",
        "/metrics",
    } <= set(document["paths"])
    post = document["paths"]["/mappings"]["post"]
    assert post["requestBody"]["content"]["application/json"]["schema"]["$ref"].endswith("/MappingBody")
    assert {"401", "409", "422"} <= set(post["responses"])


# -- fuzz: whatever the body, never a server error -------------------------------------------------
JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True) | st.text(max_size=20),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=10), inner, max_size=4),
    max_leaves=12,
)
STAGE = st.fixed_dictionaries(
    {"type": st.sampled_from(["filter", "throttle", "on_change", "project", "aggregate", "x"])},
    optional={
        "hz": JSON,
        "expr": st.text(max_size=30),
        "window": JSON,
        "fields": JSON,
        "ops": JSON,
        "name": JSON,
        "hop": JSON,
        "keep": JSON,
    },
)
MAPPING = st.fixed_dictionaries(
    {},
    optional={
        "name": st.sampled_from(["imu", "ir", "a.b", ""]) | st.text(max_size=8),
        "from": st.sampled_from(["/{robot}/imu", "/imu", "/{robot*}", "x"]) | st.text(max_size=12),
        "to": st.sampled_from(["fleet.imu", "fleet.{robot}", "{msg.zone}"]) | st.text(max_size=12),
        "key": JSON,
        "type": JSON,
        "delivery": JSON,
        "robot_type": st.sampled_from(["tb4", "ghost"]) | JSON,
        "stages": st.lists(STAGE, max_size=3) | JSON,
    },
)
REQUESTS = st.one_of(
    st.tuples(st.just("post"), st.just("/mappings"), MAPPING | JSON),
    st.tuples(
        st.just("put"), st.sampled_from(["/mappings/ir", "/mappings/imu", "/mappings/battery"]), MAPPING
    ),
    st.tuples(st.just("post"), st.just("/dry-run"), MAPPING | JSON),
    st.tuples(
        st.just("put"),
        st.sampled_from(["/robot_types/tb4", "/robot_types/kb"]),
        st.fixed_dictionaries(
            {}, optional={"match": JSON | st.just("/kb_*"), "mappings": st.lists(MAPPING, max_size=2)}
        ),
    ),
    st.tuples(
        st.just("delete"),
        st.sampled_from(["/mappings/ir", "/mappings/imu", "/robot_types/tb4", "/robot_types/x"]),
        st.none(),
    ),
)


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(REQUESTS, min_size=1, max_size=4))
def test_fuzz_no_server_error(requests: list[tuple[str, str, Any]]) -> None:
    w_ = world()
    api = client(w_)
    for method, path, body in requests:
        content = json.dumps(body, allow_nan=True).encode()
        response = api.request(
            method,
            path,
            headers={**AUTH, "content-type": "application/json"},
            content=content if body is not None else None,
        )
        assert response.status_code < 500, (method, path, body, response.text)
        if response.status_code in (200, 201):
            assert w_.service.config is not None  # the effective config validated
    for path in ("/mappings", "/topics", "/health"):
        assert api.get(path, headers=AUTH).status_code == 200
