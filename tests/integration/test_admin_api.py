"""The admin HTTP API on a real edge agent: simulated robots on a real Zenoh router.

Changes made through the API apply at once (records flow within a second), stop when removed,
are refused with the field named when invalid, survive a restart, need the token; /metrics and
/health report the live counters; the served OpenAPI document validates.

The helpers here (``running_edge``, ``fleet``, ``edge_config``) are shared by the other
``test_admin_*`` modules.
"""

from __future__ import annotations

import itertools
import logging
import socket
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import pytest
from openapi_spec_validator import validate
from prometheus_client.parser import text_string_to_metric_families
from pydantic import SecretStr

from fleetlink.common.metrics.errors import ServeError
from fleetlink.console.edge import console_extension
from fleetlink.edge.admin import EdgeAdmin
from fleetlink.edge.admin.store import default_overlay_path
from fleetlink.edge.agent import EdgeAgent
from fleetlink.edge.config import EdgeConfig
from fleetlink.roswire.sim.fleet import Fleet
from fleetlink.schemas.bundled import bundled_message_paths
from fleetlink.schemas.typestore import load_typestore
from tests.helpers import wait_until, zenoh_peer_config

TOKEN = "admin-" + uuid.uuid4().hex
AUTH = {"Authorization": f"Bearer {TOKEN}"}
_domains = itertools.count(170)


def next_domain() -> int:
    return next(_domains)


def edge_config(spool: Path, router: str, *, site: str, domain: int, **extra: Any) -> EdgeConfig:
    data: dict[str, Any] = {
        "site": site,
        "edge_id": "edge-1",
        "ros": {"domain_id": domain, "message_paths": [str(p) for p in bundled_message_paths()]},
        "zenoh": {"mode": "client", "connect": [router]},
        "robot_types": {
            "tb4": {
                "match": "/tb4_*",
                "mappings": [
                    {
                        "name": "ir",
                        "from": "/{robot}/ir_intensity",
                        "to": "fleet.ir",
                        "type": "irobot_create_msgs/msg/IrIntensityVector",
                    },
                ],
            }
        },
        "spool": {"dir": str(spool), "segment_bytes": "4MiB", "max_bytes": "64MiB"},
        "registration": {"grace_period": "1s"},
        "wan": {
            "linger": "5ms",
            "ack_timeout": "2s",
            "retry_backoff_min": "50ms",
            "retry_backoff_max": "500ms",
        },
    }
    data.update(extra)
    return EdgeConfig.model_validate(data)


@contextmanager
def fleet(
    router: str, domain: int, robots: int = 2, rate: float = 20.0, prefix: str = "tb4_"
) -> Iterator[Fleet]:
    typestore = load_typestore("jazzy", bundled_message_paths())
    config = zenoh_peer_config(router)
    with Fleet(config, typestore, robots=robots, rate=rate, domain_id=domain, prefix=prefix) as sim:
        yield sim


@dataclass
class Edge:
    agent: EdgeAgent
    admin: EdgeAdmin
    http: httpx.Client

    def counters(self, mapping: str) -> dict[str, int]:
        counts: dict[str, int] = self.agent.snapshot().get("mappings", {}).get(mapping, {})
        return counts


@contextmanager
def running_edge(config: EdgeConfig, *, token: str | None = TOKEN) -> Iterator[Edge]:
    """The agent with its admin API (config file + saved admin changes), stopped at the end."""
    secret = SecretStr(token) if token else None
    admin = EdgeAdmin(
        config, token=secret, listen="127.0.0.1:0", extensions=[console_extension(secret, config.edge_id)]
    )
    agent = EdgeAgent(admin.load(), stop_timeout_s=0.5)
    with agent:
        admin.attach(agent)
        try:
            with httpx.Client(base_url=admin.url, timeout=10) as http:
                yield Edge(agent, admin, http)
        finally:
            admin.stop()


def wait_registered(edge: Edge, robots: list[str], timeout: float = 10) -> None:
    wait_until(lambda: sorted(edge.agent.robots()) == robots, timeout, message=f"robots {robots} registered")


IMU_MAPPING = {
    "name": "imu_rt",
    "robot_type": "tb4",
    "from": "/{robot}/imu",
    "to": "fleet.imu",
    "type": "sensor_msgs/msg/Imu",
}


def site() -> str:
    return f"site-{uuid.uuid4().hex[:8]}"


def test_added_mapping_flows_within_a_second_and_stops_when_removed(
    zenoh_router: str, tmp_path: Path
) -> None:
    domain = next_domain()
    config = edge_config(tmp_path / "spool", zenoh_router, site=site(), domain=domain)
    with fleet(zenoh_router, domain) as sim, running_edge(config) as edge:
        wait_registered(edge, ["tb4_01", "tb4_02"])
        wait_until(
            lambda: edge.counters("ir").get("received", 0) > 0, 10, message="the config's mapping flows"
        )
        assert "imu_rt" not in edge.agent.snapshot().get("mappings", {})

        started = time.monotonic()
        response = edge.http.post("/mappings", headers=AUTH, json=IMU_MAPPING)
        assert response.status_code == 201, response.text
        wait_until(
            lambda: edge.counters("imu_rt").get("emitted", 0) > 0,
            1.0,
            message="records of the added mapping within a second",
        )
        took = time.monotonic() - started
        assert took < 1.0
        view = edge.http.get("/mappings/imu_rt", headers=AUTH).json()
        assert view["origin"] == "admin"
        assert sorted(view["robots"]) == ["tb4_01", "tb4_02"]
        wait_until(
            lambda: edge.http.get("/mappings/imu_rt", headers=AUTH).json()["counters"]["received"] > 0,
            2,
            message="the API shows the live counters",
        )

        assert edge.http.delete("/mappings/imu_rt", headers=AUTH).status_code == 200
        wait_until(
            lambda: not any(t.endswith("/imu") for t in edge.agent.subscribed_topics()),
            2,
            message="the imu subscriptions are dropped",
        )
        stopped_at = edge.counters("imu_rt")["received"]
        published = sim.published["imu"]
        wait_until(
            lambda: sim.published["imu"] >= published + 20, 5, message="20 more imu messages published"
        )
        assert edge.counters("imu_rt")["received"] == stopped_at
        assert edge.http.get("/mappings/imu_rt", headers=AUTH).status_code == 404


def test_invalid_mapping_is_refused_naming_the_field(zenoh_router: str, tmp_path: Path) -> None:
    config = edge_config(tmp_path / "spool", zenoh_router, site=site(), domain=next_domain())
    with running_edge(config) as edge:
        before = edge.http.get("/mappings", headers=AUTH).json()
        bad = {**IMU_MAPPING, "stages": [{"type": "throttle", "hz": 10}, {"type": "throttle", "hz": -1}]}
        response = edge.http.post("/mappings", headers=AUTH, json=bad)
        assert response.status_code == 422
        problems = response.json()["problems"]
        assert [p["path"] for p in problems] == ["stages[1].hz"]
        assert "greater than 0" in problems[0]["message"]
        not_robot = edge.http.post(
            "/mappings", headers=AUTH, json={**IMU_MAPPING, "from": "/imu", "key": "k"}
        )
        assert not_robot.status_code == 422
        assert not_robot.json()["problems"][0] == {
            "path": "from",
            "config_path": "robot_types.tb4.mappings[1].from",
            "message": "'/imu': a robot type's mappings capture the robot as one segment, "
            "e.g. '/{robot}/imu'",
        }
        assert edge.http.get("/mappings", headers=AUTH).json() == before
        assert [m.name for m in edge.agent.table.list()] == ["ir"]
        assert not default_overlay_path(tmp_path / "spool").exists()


def test_restart_keeps_the_changes(zenoh_router: str, tmp_path: Path) -> None:
    domain = next_domain()
    config = edge_config(tmp_path / "spool", zenoh_router, site=site(), domain=domain)
    with running_edge(config) as edge:
        assert edge.http.post("/mappings", headers=AUTH, json=IMU_MAPPING).status_code == 201
        assert edge.http.delete("/mappings/ir", headers=AUTH).status_code == 200
        assert edge.http.put("/robot_types/kobuki", headers=AUTH, json={"match": "/kb_*"}).status_code == 201
    overlay = default_overlay_path(tmp_path / "spool")
    assert overlay.exists()
    with fleet(zenoh_router, domain) as _sim, running_edge(config) as edge:
        listed = edge.http.get("/mappings", headers=AUTH).json()
        assert [(m["name"], m["origin"]) for m in listed] == [("imu_rt", "admin")]
        assert [t["name"] for t in edge.http.get("/robot_types", headers=AUTH).json()] == ["tb4", "kobuki"]
        wait_until(
            lambda: edge.counters("imu_rt").get("emitted", 0) > 0,
            10,
            message="the saved mapping runs after the restart",
        )
        assert "ir" not in edge.agent.snapshot()["mappings"]


def test_a_taken_admin_port_fails_attach_with_the_bind_error(zenoh_router: str, tmp_path: Path) -> None:
    """The first error reaches the caller (not one from cleaning up after it), and nothing is left running."""
    config = edge_config(tmp_path / "spool", zenoh_router, site=site(), domain=next_domain())
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        host, port = taken.getsockname()
        admin = EdgeAdmin(config, token=None, listen=f"{host}:{port}")
        with EdgeAgent(admin.load(), stop_timeout_s=0.5) as agent:
            with pytest.raises(ServeError, match="cannot listen"):
                admin.attach(agent)
            assert admin.service is None
            assert admin.http is None
            assert admin.zenoh is None
            assert admin._agent_backend is None


def test_the_api_refuses_requests_without_the_token(
    zenoh_router: str, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG)
    config = edge_config(tmp_path / "spool", zenoh_router, site=site(), domain=next_domain())
    with running_edge(config) as edge:
        statuses = []
        for headers in ({}, {"Authorization": "Bearer nope"}, {"Authorization": TOKEN}):
            for method, path in (("get", "/mappings"), ("post", "/mappings"), ("delete", "/mappings/ir")):
                response = edge.http.request(method, path, headers=headers, json=IMU_MAPPING)
                statuses.append(response.status_code)
        # no token is not a guess; the sixth wrong token locks this client out (1 s)
        assert statuses == [401] * 8 + [429]
        assert [m.name for m in edge.agent.table.list()] == ["ir"]
        wait_until(
            lambda: edge.http.get("/mappings", headers=AUTH).status_code == 200, 10, message="lockout over"
        )
        assert edge.http.get("/health").status_code == 200  # probes need no token
    assert TOKEN not in caplog.text


def test_metrics_and_health_show_the_live_counters(zenoh_router: str, tmp_path: Path) -> None:
    domain = next_domain()
    config = edge_config(tmp_path / "spool", zenoh_router, site=site(), domain=domain)
    with fleet(zenoh_router, domain) as _sim, running_edge(config) as edge:
        wait_registered(edge, ["tb4_01", "tb4_02"])
        wait_until(lambda: edge.counters("ir").get("emitted", 0) >= 5, 10, message="ir records made")

        def scrape() -> dict[tuple[str, tuple[tuple[str, str], ...]], float]:
            text = edge.http.get("/metrics").text
            return {
                (s.name, tuple(sorted(s.labels.items()))): s.value
                for fam in text_string_to_metric_families(text)
                for s in fam.samples
            }

        first = scrape()
        after = edge.counters("ir")
        received = first[("fleetlink_mapping_received_total", (("mapping", "ir"),))]
        assert 5 <= received <= after["received"]
        assert first[("fleetlink_robots_registered", ())] == 2
        assert first[("fleetlink_spool_appended_records_total", (("stream", "durable"),))] >= 5
        assert first[("fleetlink_spool_capacity_bytes", (("stream", "durable"),))] == 64 * 2**20
        wait_until(
            lambda: scrape()[("fleetlink_mapping_received_total", (("mapping", "ir"),))] > received,
            5,
            message="the counter grows between scrapes",
        )
        health = edge.http.get("/health").json()
        assert health["robots"] == 2
        # no uplink serves this site: the WAN link is down and the records wait in the spool
        wait_until(
            lambda: edge.http.get("/health").json()["wan_link_up"] is False, 10, message="WAN seen down"
        )
        health = edge.http.get("/health")
        assert health.status_code == 200
        assert health.json()["state"] == "degraded"
        assert ("wan", "wan_down") in [(p["component"], p["reason"]) for p in health.json()["problems"]]


def test_served_openapi_document_validates(zenoh_router: str, tmp_path: Path) -> None:
    config = edge_config(tmp_path / "spool", zenoh_router, site=site(), domain=next_domain())
    with running_edge(config) as edge:
        document = httpx.get(f"{edge.admin.url}/openapi.json", timeout=5).json()
    validate(document)
    assert document["info"]["title"] == "fleetlink edge admin"
