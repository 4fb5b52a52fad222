"""The console's JSON and HTML endpoints on running processes.

- the edge's console (under /console/ of its admin server) on a real edge agent with simulated
  robots on a real Zenoh router: refused without the token, sign-in, the site view with live
  rates, a mapping added / refused / tried / removed through it;
- the uplink's fleet console, reaching the site over the Zenoh admin space across two linked
  routers (the WAN hop): the site is listed, its view carries live topic rates and the Kafka
  delivery latency the uplink measured, a mapping added there lands in Kafka, a bad one is
  refused with its field named.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import httpx
import zenoh

from fleetlink.console.auth import COOKIE
from tests.browser.stack import console_stack
from tests.helpers import wait_until, zenoh_peer_config
from tests.integration.e2e_stack import TopicReader, headers
from tests.integration.test_admin_api import AUTH, TOKEN, edge_config, fleet, next_domain, running_edge, site

CHANGE = {**AUTH, "X-Fleetlink-Console": "1"}


def rate_of(view: dict[str, Any], node_id: str) -> float:
    for column in ("topics", "kafka"):
        for node in view["graph"][column]:
            if node["id"] == node_id:
                return float(node["rate"] or 0.0)
    return 0.0


def test_edge_console_on_a_live_edge(zenoh_router: str, tmp_path: Path) -> None:
    name, domain = site(), next_domain()
    config = edge_config(tmp_path / "spool", zenoh_router, site=name, domain=domain)
    with fleet(zenoh_router, domain) as _sim, running_edge(config) as edge:
        base = f"{edge.admin.url}/console/"
        anonymous = httpx.Client(base_url=base, timeout=10)
        assert anonymous.get(f"api/sites/{name}").status_code == 401
        assert anonymous.get(f"api/sites/{name}", headers={"Authorization": "Bearer nope"}).status_code == 401
        page = anonymous.get(f"sites/{name}", follow_redirects=False)
        assert (page.status_code, page.headers["location"]) == (
            303,
            f"/console/login?next=/console/sites/{name}",
        )
        refused = anonymous.post(
            f"api/sites/{name}/mappings", json={"name": "x", "from": "/{robot}/x", "to": "t"}
        )
        assert refused.status_code == 401
        assert "x" not in [m.name for m in edge.agent.table.list()]

        signed = httpx.Client(base_url=base, timeout=10, follow_redirects=True)
        login = signed.post("login", data={"token": TOKEN, "next": f"/console/sites/{name}"})
        assert login.status_code == 200
        assert signed.cookies.get(COOKIE)
        assert f'data-site="{name}"' in login.text
        assert signed.get("static/console.js").status_code == 200

        http = httpx.Client(base_url=base, headers=AUTH, timeout=10)
        views: list[dict[str, Any]] = []

        def live() -> bool:
            views.append(http.get(f"api/sites/{name}").json())
            return rate_of(views[-1], "t:/tb4_01/ir_intensity") > 0

        wait_until(live, 15, interval=0.3, message="a live rate for /tb4_01/ir_intensity")
        view = views[-1]
        assert [(r["robot"], r["state"]) for r in view["robots"]] == [
            ("tb4_01", "registered"),
            ("tb4_02", "registered"),
        ]
        assert [n["id"] for n in view["graph"]["robots"]][:2] == ["r:tb4_01", "r:tb4_02"]
        ir = next(m for m in view["mappings"] if m["name"] == "ir")
        assert ir["rates"]["received"] is not None
        assert ir["rates"]["received"] > 0
        assert view["status"]["streams"][0]["stream"] == "durable"
        assert view["status"]["topics"]["/tb4_01/ir_intensity"]["received"] > 0
        assert view["health"]["state"] in ("ok", "degraded")
        assert view["errors"] == {}

        bad = {
            "name": "imu_bad",
            "robot_type": "tb4",
            "from": "/{robot}/imu",
            "to": "fleet.imu",
            "stages": "- {type: throttle, hz: 0}",
        }
        answer = http.post(f"api/sites/{name}/mappings", json=bad, headers=CHANGE)
        assert answer.status_code == 422
        assert answer.json()["fields"] == {"stages": ["stages[0].hz: Input should be greater than 0"]}
        assert "imu_bad" not in [m.name for m in edge.agent.table.list()]

        tried = http.post(f"api/sites/{name}/dry-run", json={**bad, "stages": ""}, headers=CHANGE)
        assert sorted(m["topic"] for m in tried.json()["result"]["matches"]) == ["/tb4_01/imu", "/tb4_02/imu"]

        added = http.post(
            f"api/sites/{name}/mappings", json={**bad, "name": "imu_c", "stages": ""}, headers=CHANGE
        )
        assert added.status_code == 201, added.text
        wait_until(lambda: edge.counters("imu_c").get("emitted", 0) > 0, 5, message="the added mapping flows")
        removed = http.delete(f"api/sites/{name}/mappings/imu_c", headers=CHANGE)
        assert removed.status_code == 200
        assert "imu_c" not in [m["name"] for m in http.get(f"api/sites/{name}").json()["mappings"]]
        commands = http.get("api/commands").json()
        assert (commands["process"], commands["available"]) == ("edge", False)


def test_fleet_console_over_the_zenoh_admin_space(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    with console_stack(kafka_bootstrap, schema_registry_url, tmp_path) as stack:
        base = stack.fleet_console
        assert httpx.get(f"{base}api/sites", timeout=10).status_code == 401
        http = stack.client(base)

        def listed() -> list[dict[str, Any]]:
            found: list[dict[str, Any]] = http.get("api/sites").json()["sites"]
            return [s for s in found if s["site"] == stack.site]

        wait_until(listed, 10, interval=0.2, message="the site answers the fleet console")
        [summary] = listed()
        assert (summary["edge_id"], summary["robots"], summary["error"]) == ("edge-1", 2, None)
        assert summary["state"] in ("ok", "degraded")

        views: list[dict[str, Any]] = []

        def live() -> bool:
            views.append(http.get(f"api/sites/{stack.site}").json())
            view = views[-1]
            return rate_of(view, "t:/tb4_02/ir_intensity") > 0 and view["latency"] is not None

        wait_until(live, 20, interval=0.3, message="live rates and a delivery latency over Zenoh")
        view = views[-1]
        assert (view["process"], view["site"], view["edge_id"], view["errors"]) == (
            "uplink",
            stack.site,
            "edge-1",
            {},
        )
        assert [r["robot"] for r in view["robots"]] == ["tb4_01", "tb4_02"]
        assert view["latency"]["batches"] > 0
        assert view["status"]["wan_link_up"] is True
        assert rate_of(view, "k:fleet.ir") >= 0  # the Kafka node is there (its rate may still be measuring)
        assert "k:fleet.ir" in [n["id"] for n in view["graph"]["kafka"]]

        topic = f"console.imu.{stack.suffix}"
        form = {
            "name": "imu_fleet",
            "robot_type": "tb4",
            "from": "/{robot}/imu",
            "to": topic,
            "type": "sensor_msgs/msg/Imu",
            "stages": "- {type: throttle, hz: 5}",
        }
        change = {"X-Fleetlink-Console": "1"}
        bad = http.post(
            f"api/sites/{stack.site}/mappings", json={**form, "to": "no spaces allowed"}, headers=change
        )
        assert bad.status_code == 422
        assert list(bad.json()["fields"]) == ["to"]
        added = http.post(f"api/sites/{stack.site}/mappings", json=form, headers=change)
        assert added.status_code == 201, added.text
        assert "imu_fleet" in [m.name for m in stack.agent.table.list()]
        records = TopicReader(stack.bootstrap, stack.registry_url).read(topic, 4, timeout=20)
        assert {headers(m)["fleetlink.mapping"] for m in records} == {"imu_fleet"}
        assert {(m.key() or b"").decode() for m in records} <= {"tb4_01", "tb4_02"}
        commands = http.get("api/commands").json()
        assert commands["available"] is False
        assert "no command mappings" in commands["reason"]


def test_status_key_refuses_without_the_token(zenoh_router: str, tmp_path: Path) -> None:
    """The fleet console's status key answers only to the admin token (like the admin space)."""
    name, domain = site(), next_domain()
    config = edge_config(tmp_path / "spool", zenoh_router, site=name, domain=domain)
    with running_edge(config) as edge:
        assert len(edge.admin.extensions) == 1
        session = zenoh.open(zenoh_peer_config(zenoh_router, mode="client"))
        try:
            key = f"fleetlink/{name}/console/status"

            def ask(attachment: bytes | None) -> list[dict[str, Any]]:
                return [
                    json.loads(r.ok.payload.to_bytes())
                    for r in session.get(key, attachment=attachment, timeout=5)
                    if r.ok is not None
                ]

            wait_until(lambda: ask(None), 10, message="the status key answers")
            [refused] = ask(None)
            assert (refused["status"], refused["site"]) == (401, name)
            assert "body" not in refused
            [answer] = ask(f"Bearer {TOKEN}".encode())
            assert answer["status"] == 200
            assert answer["body"]["streams"][0]["stream"] == "durable"
        finally:
            session.close()
