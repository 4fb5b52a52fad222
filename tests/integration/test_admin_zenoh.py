"""The Zenoh admin space of a real edge, queried from the cloud side: the edge on a site router, the
querier on a cloud router linked to it (the WAN hop). Replies come back on concrete keys."""

from __future__ import annotations

import json
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh

from fleetlink.localstack.zenoh_router import ZenohRouter
from tests.helpers import wait_until, zenoh_peer_config
from tests.integration.test_admin_api import TOKEN, edge_config, fleet, next_domain, running_edge

BEARER = f"Bearer {TOKEN}".encode()


@pytest.fixture
def cloud(zenoh_router: str) -> Iterator[zenoh.Session]:
    """A client session on a cloud router that is linked to the site router."""
    with ZenohRouter(connect=(zenoh_router,)) as router:
        session = zenoh.open(zenoh_peer_config(router.endpoint, mode="client"))
        try:
            yield session
        finally:
            session.close()


def ask(
    session: zenoh.Session, selector: str, payload: Any = None, *, attachment: bytes | None = BEARER
) -> list[tuple[str, dict[str, Any]]]:
    """Every ok reply as (key, envelope); error replies fail the test."""
    body = None if payload is None else json.dumps(payload).encode()
    out = []
    for reply in session.get(selector, payload=body, attachment=attachment, timeout=5.0):
        if reply.ok is None:
            raise AssertionError(f"error reply: {reply.err}")
        out.append((str(reply.ok.key_expr), json.loads(reply.ok.payload.to_bytes())))
    return out


def test_admin_space_answers_across_routers(zenoh_router: str, cloud: zenoh.Session, tmp_path: Path) -> None:
    site = f"site-{uuid.uuid4().hex[:8]}"
    domain = next_domain()
    prefix = f"fleetlink/{site}/admin"
    config = edge_config(tmp_path / "spool", zenoh_router, site=site, domain=domain)
    with fleet(zenoh_router, domain) as _sim, running_edge(config) as edge:
        wait_until(
            lambda: len(ask(cloud, f"{prefix}/health")) == 1, 10, message="the admin space is reachable"
        )

        [(key, reply)] = ask(cloud, f"{prefix}/mappings")
        assert key == f"{prefix}/mappings"
        assert (reply["status"], reply["site"], reply["edge_id"]) == (200, site, "edge-1")
        assert [m["name"] for m in reply["body"]] == ["ir"]

        # a wildcard over every site: this edge answers on its concrete key
        replies = ask(cloud, "fleetlink/*/admin/health")
        assert [k for k, _ in replies] == [f"{prefix}/health"]
        assert replies[0][1]["body"]["state"] in ("ok", "degraded")

        mapping = {"name": "imu_z", "robot_type": "tb4", "from": "/{robot}/imu", "to": "fleet.imu"}
        [(key, reply)] = ask(cloud, f"{prefix}/mappings?op=add", mapping)
        assert (key, reply["status"], reply["body"]["status"]) == (f"{prefix}/mappings", 201, "created")
        assert "imu_z" in [m.name for m in edge.agent.table.list()]
        wait_until(lambda: edge.counters("imu_z").get("emitted", 0) > 0, 5, message="the added mapping flows")

        items = {k.rsplit("/", 1)[1]: r["body"]["name"] for k, r in ask(cloud, f"{prefix}/mappings/*")}
        assert items == {"ir": "ir", "imu_z": "imu_z"}

        bad = {**mapping, "name": "imu_bad", "stages": [{"type": "throttle", "hz": 0}]}
        [(key, reply)] = ask(cloud, f"{prefix}/mappings", bad)
        assert reply["status"] == 422
        assert [p["path"] for p in reply["problems"]] == ["stages[0].hz"]

        [(key, reply)] = ask(cloud, f"{prefix}/mappings/imu_z?op=delete", attachment=None)
        assert reply["status"] == 401
        assert "imu_z" in [m.name for m in edge.agent.table.list()]

        [(key, reply)] = ask(cloud, f"{prefix}/mappings/imu_z?op=delete")
        assert (key, reply["status"]) == (f"{prefix}/mappings/imu_z", 200)
        assert [m.name for m in edge.agent.table.list()] == ["ir"]

        [(_, reply)] = ask(cloud, f"{prefix}/dry-run", {"from": "/{robot}/odom", "to": "fleet.odom"})
        assert sorted(m["topic"] for m in reply["body"]["matches"]) == ["/tb4_01/odom", "/tb4_02/odom"]
