"""The console's web app in process (FastAPI TestClient, no sockets): access, sign-in, pages, the
site view with rates, and mapping changes with their errors put on the form's fields. The edge's
console runs on a real ``AdminService`` (the admin tests' small world); a fixed ``Sites`` stands
in for the fleet (the Zenoh source is tested on real routers in tests/integration)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from pydantic import SecretStr

from fleetlink.console.app import create_console_app
from fleetlink.console.auth import COOKIE, cookie_value
from fleetlink.console.edge import EdgeConsole
from fleetlink.console.envelope import Envelope, failure
from fleetlink.console.sources import Process
from fleetlink.console.users import User, hash_password
from fleetlink.edge.admin.backend import EdgeSnapshot, MappingCounts
from fleetlink.edge.admin.http import create_app
from tests.unit.edge.admin.world import World, world

TOKEN = "console-" + "t" * 16
BEARER = {"Authorization": f"Bearer {TOKEN}"}
CHANGE = {**BEARER, "X-Fleetlink-Console": "1"}
SITE = "warehouse-a"
IMU = {"name": "imu", "robot_type": "tb4", "from": "/{robot}/imu", "to": "fleet.imu"}


class Clock:
    def __init__(self) -> None:
        self.now = 1_000.0

    def __call__(self) -> float:
        return self.now


def edge_client(
    w: World, *, token: str | None = TOKEN, clock: Clock | None = None, users: dict[str, User] | None = None
) -> TestClient:
    secret = SecretStr(token) if token else None
    raw = {"subscriptions": {"/tb4_01/ir_intensity": {"received": 0}}}
    console = EdgeConsole(
        w.service,
        edge_id="edge-1",
        token=secret,
        snapshot=w.backend.snapshot,
        raw_snapshot=lambda: raw,
        clock=clock or Clock(),
        users=users,
    )
    app = create_app(w.service, token=secret)
    console.mount(app)
    client = TestClient(app, raise_server_exceptions=False)
    client.raw = raw  # type: ignore[attr-defined,unused-ignore]  # TestClient typing differs by httpx flavour
    return client


@pytest.fixture
def w(tmp_path: Path) -> World:
    return world()


PAGES = ["/console/", f"/console/sites/{SITE}"]
API = [
    ("get", "/console/api/sites"),
    ("get", f"/console/api/sites/{SITE}"),
    ("get", "/console/api/commands"),
    ("post", f"/console/api/sites/{SITE}/mappings"),
    ("put", f"/console/api/sites/{SITE}/mappings/ir"),
    ("delete", f"/console/api/sites/{SITE}/mappings/ir"),
    ("post", f"/console/api/sites/{SITE}/dry-run"),
]
WRONG = [
    {},
    {"Authorization": "Bearer wrong"},
    {"Authorization": f"Basic {TOKEN}"},
    {"Cookie": f"{COOKIE}={TOKEN}"},
    {"Cookie": f"{COOKIE}={cookie_value(SecretStr('other'), now=1_000.0)}"},
    {"Cookie": f"{COOKIE}={cookie_value(SecretStr(TOKEN), now=1_000.0 - 9 * 3600)}"},  # expired
]


@pytest.mark.parametrize("headers", WRONG)
@pytest.mark.parametrize(("method", "path"), API)
def test_every_api_route_refuses_without_the_token(
    w: World, method: str, path: str, headers: dict[str, str]
) -> None:
    response = edge_client(w).request(
        method,
        path,
        headers={**headers, "X-Fleetlink-Console": "1"},
        json={"name": "x", "from": "/{robot}/x", "to": "t"},
    )
    assert response.status_code == 401
    assert response.json()["ok"] is False
    assert TOKEN not in response.text
    assert w.backend.installs == 0


@pytest.mark.parametrize("headers", WRONG)
@pytest.mark.parametrize("path", PAGES)
def test_pages_send_strangers_to_the_sign_in_form(w: World, path: str, headers: dict[str, str]) -> None:
    response = edge_client(w).get(path, headers=headers, follow_redirects=False)
    assert response.status_code == 303
    assert response.headers["location"] == f"/console/login?next={path}"
    assert SITE not in response.text


def test_the_assets_and_the_sign_in_form_are_open(w: World) -> None:
    client = edge_client(w)
    for path, kind in (
        ("/console/static/console.js", "javascript"),
        ("/console/static/console.css", "text/css"),
        ("/console/login", "text/html"),
    ):
        response = client.get(path)
        assert response.status_code == 200
        assert kind in response.headers["content-type"]
    page = client.get("/console/login?next=/console/sites/x")
    assert 'name="next" value="/console/sites/x"' in page.text
    assert "default-src 'self'" in page.headers["content-security-policy"]
    assert page.headers["x-content-type-options"] == "nosniff"


def test_sign_in_sets_a_cookie_that_opens_the_console(w: World) -> None:
    client = edge_client(w)
    wrong = client.post("/console/login", data={"token": "nope", "next": "/console/"}, follow_redirects=False)
    assert wrong.status_code == 401
    assert "wrong token" in wrong.text
    assert "set-cookie" not in wrong.headers
    right = client.post(
        "/console/login", data={"token": TOKEN, "next": f"/console/sites/{SITE}"}, follow_redirects=False
    )
    assert (right.status_code, right.headers["location"]) == (303, f"/console/sites/{SITE}")
    cookie = right.headers["set-cookie"]
    assert cookie.startswith(f"{COOKIE}={cookie_value(SecretStr(TOKEN), now=1_000.0)};")
    assert TOKEN not in cookie
    for flag in ("HttpOnly", "Path=/console/", "SameSite=strict"):
        assert flag in cookie
    page = client.get(f"/console/sites/{SITE}")
    assert page.status_code == 200
    assert f'data-site="{SITE}"' in page.text
    assert client.get("/console/api/sites").json()["sites"][0]["site"] == SITE
    # a change with the cookie alone (what a cross-site form could send) is refused
    refused = client.post(f"/console/api/sites/{SITE}/mappings", json=IMU)
    assert refused.status_code == 403
    assert w.backend.installs == 0
    added = client.post(f"/console/api/sites/{SITE}/mappings", json=IMU, headers={"X-Fleetlink-Console": "1"})
    assert added.status_code == 201, added.text
    assert w.backend.installs == 1
    out = client.post("/console/logout", follow_redirects=False)
    assert out.status_code == 303
    assert f'{COOKIE}=""' in out.headers["set-cookie"]
    assert client.get("/console/api/sites").status_code == 401


@pytest.mark.parametrize(
    ("wanted", "goes_to"),
    [
        (f"/console/sites/{SITE}", f"/console/sites/{SITE}"),
        ("", "/console/"),
        ("https://evil.example/", "/console/"),
        ("//evil.example/", "/console/"),
        ("/elsewhere", "/console/"),
        ("/console/../mappings", "/console/"),
        ("/console/\\evil", "/console/"),
    ],
)
def test_after_sign_in_only_console_paths(w: World, wanted: str, goes_to: str) -> None:
    response = edge_client(w).post(
        "/console/login", data={"token": TOKEN, "next": wanted}, follow_redirects=False
    )
    assert response.headers["location"] == goes_to


def test_an_open_console_without_a_token(w: World) -> None:
    client = edge_client(w, token=None)
    assert client.get("/console/api/sites").status_code == 200
    front = client.get("/console/", follow_redirects=False)
    assert (front.status_code, front.headers["location"]) == (303, f"/console/sites/{SITE}")
    assert "Sign out" not in client.get(f"/console/sites/{SITE}").text
    assert client.post(f"/console/api/sites/{SITE}/mappings", json=IMU).status_code == 201


def test_the_console_is_not_part_of_the_admin_api_document(w: World) -> None:
    paths = edge_client(w).get("/openapi.json").json()["paths"]
    assert paths
    assert not [p for p in paths if p.startswith("/console")]


def test_the_site_view_with_rates_between_polls(w: World) -> None:
    clock = Clock()
    client = edge_client(w, clock=clock)
    w.snapshot[0] = EdgeSnapshot(mappings={"ir": MappingCounts(received=100, emitted=20, dropped=80)})
    first = client.get(f"/console/api/sites/{SITE}", headers=BEARER).json()
    assert first["mappings"][1]["name"] == "ir"
    assert first["mappings"][1]["rates"]["received"] is None
    clock.now += 2.0
    w.snapshot[0] = EdgeSnapshot(mappings={"ir": MappingCounts(received=140, emitted=28, dropped=112)})
    client.raw["subscriptions"]["/tb4_01/ir_intensity"]["received"] = 44  # type: ignore[attr-defined,unused-ignore]  # TestClient typing differs by httpx flavour
    view = client.get(f"/console/api/sites/{SITE}", headers=BEARER).json()
    assert view["mappings"][1]["rates"] == {
        "received": 20.0,
        "emitted": 4.0,
        "filtered": 0.0,
        "dropped": 16.0,
        "dead_lettered": 0.0,
    }
    assert view["topic_rates"] == {"/tb4_01/ir_intensity": 22.0}
    nodes = {n["id"]: n for n in view["graph"]["topics"]}
    assert nodes["t:/tb4_01/ir_intensity"]["rate"] == 22.0
    assert [n["id"] for n in view["graph"]["robots"]][:1] == ["r:tb4_01"]
    assert (view["process"], view["latency"], view["errors"]) == ("edge", None, {})
    assert view["robot_types"] == ["tb4"]
    assert view["status"]["topics"]["/tb4_01/ir_intensity"]["received"] == 44


def test_another_site_is_not_served_here(w: World) -> None:
    view = edge_client(w).get("/console/api/sites/elsewhere", headers=BEARER).json()
    assert view["errors"]["mappings"] == "404: this edge serves site 'warehouse-a', not 'elsewhere'"
    assert view["mappings"] == []


@pytest.mark.parametrize(
    ("form", "status", "fields"),
    [
        (
            {**IMU, "name": "imu_bad", "stages": "- {type: throttle, hz: 0}"},
            422,
            {"stages": ["stages[0].hz: Input should be greater than 0"]},
        ),
        ({**IMU, "name": "imu_bad", "stages": "- {type: throttle, hz: 2"}, 422, {"stages": None}),
        ({**IMU, "name": "imu_bad", "from": "imu"}, 422, {"from": None}),
        ({**IMU, "name": "imu_bad", "robot_type": "nosuch"}, 422, {"robot_type": None}),
        ({**IMU, "name": ""}, 422, {"name": None}),
        ({**IMU, "name": "ir"}, 409, {"name": None}),
        ({"name": "imu_bad", "to": "fleet.imu"}, 422, {"from": None}),
    ],
)
def test_refused_mappings_name_their_field(
    w: World, form: dict[str, str], status: int, fields: dict[str, list[str] | None]
) -> None:
    response = edge_client(w).post(f"/console/api/sites/{SITE}/mappings", json=form, headers=CHANGE)
    assert response.status_code == status, response.text
    body = response.json()
    assert body["ok"] is False
    assert set(body["fields"]) == set(fields)
    for field, messages in fields.items():
        assert body["fields"][field]
        if messages is not None:
            assert body["fields"][field] == messages
    assert w.backend.installs == 0


def test_add_change_dry_run_and_remove(w: World) -> None:
    client = edge_client(w)
    added = client.post(
        f"/console/api/sites/{SITE}/mappings",
        json={**IMU, "stages": "- {type: throttle, hz: 2}"},
        headers=CHANGE,
    )
    assert added.status_code == 201
    assert added.json()["result"] == {"status": "created", "kind": "mapping", "name": "imu", "overlay": None}
    assert "imu" in [m.name for m in w.table.list()]
    changed = client.put(
        f"/console/api/sites/{SITE}/mappings/imu", json={**IMU, "to": "fleet.imu2"}, headers=CHANGE
    )
    assert changed.status_code == 200, changed.text
    mapping = next(m for m in w.service.mappings() if m.name == "imu")
    assert (mapping.to, mapping.stages) == ("fleet.imu2", [])
    bad_change = client.put(f"/console/api/sites/{SITE}/mappings/imu", json={**IMU, "to": ""}, headers=CHANGE)
    assert bad_change.status_code == 422
    assert "to" in bad_change.json()["fields"]
    dry = client.post(
        f"/console/api/sites/{SITE}/dry-run",
        json={"from": "/{robot}/battery_state", "to": "fleet.b", "robot_type": "tb4"},
        headers=CHANGE,
    )
    assert dry.status_code == 200
    matches = dry.json()["result"]["matches"]
    assert [(m["topic"], m["registered"]) for m in matches] == [
        ("/tb4_01/battery_state", True),
        ("/tb4_02/battery_state", False),
    ]
    bad_dry = client.post(
        f"/console/api/sites/{SITE}/dry-run", json={"from": "nope", "to": "x"}, headers=CHANGE
    )
    assert bad_dry.status_code == 422
    assert "from" in bad_dry.json()["fields"]
    removed = client.delete(f"/console/api/sites/{SITE}/mappings/imu", headers=CHANGE)
    assert removed.status_code == 200
    assert "imu" not in [m.name for m in w.table.list()]
    missing = client.delete(f"/console/api/sites/{SITE}/mappings/imu", headers=CHANGE)
    assert missing.status_code == 404
    assert missing.json()["fields"] == {"_form": ["no mapping named 'imu'"]}


@pytest.mark.parametrize(
    ("method", "path", "body"),
    [
        ("post", f"/console/api/sites/{SITE}/mappings", {"name": 3}),
        ("post", f"/console/api/sites/{SITE}/mappings", {"name": "x", "evil": "1"}),
        ("post", f"/console/api/sites/{SITE}/mappings", ["not", "an", "object"]),
        ("get", "/console/api/sites/bad%2Asite", None),
        ("delete", f"/console/api/sites/{SITE}/mappings/a%20b", None),
    ],
)
def test_malformed_requests_are_refused_in_the_same_shape(
    w: World, method: str, path: str, body: Any
) -> None:
    response = edge_client(w).request(method, path, json=body, headers=CHANGE)
    assert response.status_code == 422
    assert response.json()["ok"] is False
    assert w.backend.installs == 0


def test_commands_are_not_kept_by_an_edge(w: World) -> None:
    body = edge_client(w).get("/console/api/commands", headers=BEARER).json()
    assert body == {
        "process": "edge",
        "available": False,
        "reason": "not available on this process: command status is kept by the uplink (see its console)",
    }


class FixedFleet:
    """Two sites as the uplink's Zenoh source would report them."""

    def __init__(self) -> None:
        self.asked: list[tuple[str, str, str | None, Any]] = []

    @property
    def process(self) -> Process:
        return "uplink"

    def sites(self) -> list[dict[str, Any]]:
        return [{"site": "a", "state": "ok"}, {"site": "b", "state": None, "error": "timeout"}]

    def read(self, site: str, names: Sequence[str] | None = None) -> dict[str, Envelope]:
        return {"health": Envelope(status=200, site=site, edge_id="e", body={"state": "ok"})}

    def ask(self, site: str, path: str, *, op: str | None = None, body: Any = None) -> Envelope:
        self.asked.append((site, path, op, body))
        return failure(504, f"no edge of site {site!r} answered within 3 s", site=site)

    def delivery(self, site: str | None) -> list[dict[str, Any]] | None:
        """Two uplinks, each having delivered some of site a's batches."""
        answers = [
            {
                "uplink": uplink,
                "site": "a",
                "batches": {"ok": n},
                "records": 10 * n,
                "dead_lettered": 0,
                "topics": {"fleet.ir": 10 * n},
                "latency": {"batches": n, "max_ms": 9.0, "samples_ms": [5.0] * n, "window_s": 60.0},
            }
            for uplink, n in (("up-1", 3), ("up-2", 2))
        ]
        return [a for a in answers if site in (None, a["site"])]

    def latest(self, site: str, robot: str) -> Envelope | None:
        return Envelope(status=200, site=site, body={"robot": robot, "values": {}})

    def commands(self) -> dict[str, Any]:
        return {"available": True, "records": 3}


def test_the_fleet_pages() -> None:
    fleet = FixedFleet()
    client = TestClient(create_console_app(fleet, token=SecretStr(TOKEN)), raise_server_exceptions=False)
    page = client.get("/", headers=BEARER)
    assert page.status_code == 200
    assert 'data-page="fleet"' in page.text
    assert client.get("/api/sites", headers=BEARER).json()["sites"][1]["error"] == "timeout"
    view = client.get("/api/sites/a", headers=BEARER).json()
    assert (view["process"], view["latency"]["p50_ms"], view["health"]) == ("uplink", 5.0, {"state": "ok"})
    assert view["latency"]["batches"] == 5  # every uplink's batches, not one uplink's
    assert (view["delivery"]["batches"], view["delivery"]["uplink_count"]) == ({"ok": 5}, 2)
    fleetwide = client.get("/api/delivery", headers=BEARER).json()
    assert (fleetwide["available"], fleetwide["records"], fleetwide["topics"]["fleet.ir"]["acked"]) == (
        True,
        50,
        50,
    )
    assert client.get("/api/commands", headers=BEARER).json() == {
        "process": "uplink",
        "available": True,
        "records": 3,
    }
    timeout = client.post("/api/sites/b/mappings", json=IMU, headers=CHANGE)
    assert timeout.status_code == 504
    assert timeout.json()["fields"] == {"_form": ["no edge of site 'b' answered within 3 s"]}
    assert client.delete("/api/sites/b/mappings/imu", headers=CHANGE).status_code == 504
    client.put("/api/sites/b/mappings/imu", json={"to": "x"}, headers=CHANGE)
    assert fleet.asked == [
        ("b", "mappings", "add", IMU),
        ("b", "mappings/imu", "delete", None),
        ("b", "mappings/imu", "put", {"to": "x"}),
    ]


def test_a_session_ends_after_its_time(w: World) -> None:
    clock = Clock()
    client = edge_client(w, clock=clock)
    client.post("/console/login", data={"token": TOKEN, "next": "/console/"}, follow_redirects=False)
    assert client.get("/console/api/sites").status_code == 200
    clock.now += 8 * 3600 + 1
    assert client.get("/console/api/sites").status_code == 401


def test_wrong_tokens_lock_a_client_out(w: World) -> None:
    client = edge_client(w)
    answers = [
        client.post("/console/login", data={"token": f"guess-{i}", "next": "/console/"}).status_code
        for i in range(200)
    ]
    assert answers[:5] == [401] * 5  # five tries are checked ...
    assert set(answers[5:]) == {429}  # ... then every attempt is refused unchecked
    locked = client.post("/console/login", data={"token": TOKEN, "next": "/console/"}, follow_redirects=False)
    assert locked.status_code == 429  # even the right token waits out the lockout
    bearer = client.get("/console/api/sites", headers={"Authorization": "Bearer nope"})
    assert bearer.status_code == 429
    assert int(bearer.headers["retry-after"]) >= 1


SAM = User("sam", "viewer", hash_password("viewer-pass-1", salt=b"s" * 16))
LIN = User("lin", "operator", hash_password("operator-pass-1", salt=b"l" * 16))


def test_named_users_sign_in_with_their_role_for_the_session_time(w: World) -> None:
    clock = Clock()
    client = edge_client(w, clock=clock, users={"sam": SAM, "lin": LIN})
    form = {"user": "sam", "token": "viewer-pass-1", "next": "/console/"}
    assert client.post("/console/login", data=form, follow_redirects=False).status_code == 303
    assert client.get("/console/api/me").json() == {"user": "sam", "role": "viewer", "process": "edge"}
    page_change = {"X-Fleetlink-Console": "1"}
    refused = client.post(f"/console/api/sites/{SITE}/mappings", json=IMU, headers=page_change)
    assert refused.status_code == 403
    assert "operator" in refused.json()["error"]
    clock.now += 8 * 3600 + 1
    assert client.get("/console/api/me").status_code == 401
    added = client.post(
        f"/console/api/sites/{SITE}/mappings", json=IMU, auth=("lin", "operator-pass-1"), headers=page_change
    )
    assert added.status_code == 201, added.text
    audit = client.get("/console/api/audit", headers=BEARER).json()
    assert [(r["user"], r["action"], r["target"], r["status"]) for r in audit["records"]] == [
        ("lin", "mapping.add", "imu", 201)
    ]


def test_wrong_passwords_lock_a_client_out(w: World) -> None:
    client = edge_client(w, users={"lin": LIN})
    answers = [client.get("/console/api/sites", auth=("lin", f"guess-{i}")).status_code for i in range(20)]
    assert answers[:5] == [401] * 5
    assert set(answers[5:]) == {429}
    form = {"user": "lin", "token": "operator-pass-1", "next": "/console/"}
    assert client.post("/console/login", data=form, follow_redirects=False).status_code == 429


def test_an_admin_page_reads_with_the_cookie_alone_but_changes_need_the_header(w: World) -> None:
    client = edge_client(w)
    client.post("/console/login", data={"token": TOKEN, "next": "/console/"}, follow_redirects=False)
    assert client.get("/console/api/audit").status_code == 200  # what the audit page polls
    assert client.post(f"/console/api/sites/{SITE}/mappings", json=IMU).status_code == 403
