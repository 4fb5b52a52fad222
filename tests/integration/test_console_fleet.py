"""The fleet console with two sites and two uplinks, linked as in deploy/compose (each site's
router joined to one cloud router, every robot in the same ROS domain, so each edge sees the
other site's robots on the ROS graph), on real processes (Kafka, registry, Zenoh routers,
uplinks, edge agents, simulated robots):

- a site's view shows that site alone: its own robots, never the other site's, never
  fleetlink's own namespace; a robot says when it registered and that it matched a robot type;
- uplink 1 serves site A's batches and uplink 2 site B's (``ingest.sites``), yet each uplink's
  console shows the delivery of both: the Kafka column of site B on uplink 1's console is what
  uplink 2 had Kafka acknowledge, and the fleet-wide figures add up both uplinks;
- named users with roles: a viewer reads but may not change, an operator adds a mapping, a
  wrong password is refused, and each change lands in the audit topic with who made it;
- the robot page, the history, the dead-letter browser and the robot-type editor's checks;
- with site B's only uplink stopped (a WAN outage for it), its Kafka column shows 0 while its
  mapping keeps producing into the spool, whose backlog shows.
"""

from __future__ import annotations

import json
import uuid
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import pytest
from confluent_kafka import Consumer

from fleetlink.common.console_config import ConsoleSection
from fleetlink.console.uplink import UplinkConsole, console_extensions
from fleetlink.console.users import hash_password
from fleetlink.edge.agent import EdgeAgent
from fleetlink.localstack.zenoh_router import ZenohRouter
from fleetlink.schemas.bundled import bundled_message_paths
from fleetlink.uplink.service import Uplink
from tests.browser.stack import IR_MAPPING, console_agent
from tests.helpers import wait_until
from tests.integration.e2e_stack import Cloud, edge_config, unique_site, uplink_config
from tests.integration.test_admin_api import fleet, next_domain

PASSWORDS = {"sam": "viewer-pass-1", "lin": "operator-pass-1"}
CHANGE = {"X-Fleetlink-Console": "1"}


@dataclass
class Fleet2:
    sites: tuple[str, str]
    consoles: tuple[str, str]
    uplinks: tuple[Uplink, Uplink]
    token: str
    audit_topic: str
    suffix: str
    bootstrap: str
    routers: tuple[str, str]
    """Each site's router (Zenoh endpoint)."""
    domain: int


@contextmanager
def two_sites(bootstrap: str, registry_url: str, tmp_path: Path) -> Iterator[Fleet2]:
    suffix = uuid.uuid4().hex[:8]
    token = f"console-{uuid.uuid4().hex}"
    (tmp_path / "token").write_text(token + "\n")
    users = tmp_path / "users.yaml"
    users.write_text(
        "users:\n"
        + "".join(
            f"  - {{name: {name}, role: {role}, password_hash: '{hash_password(PASSWORDS[name])}'}}\n"
            for name, role in (("sam", "viewer"), ("lin", "operator"))
        )
    )
    sites = (unique_site(), unique_site())
    domain = next_domain()
    paths = [str(p) for p in bundled_message_paths()]
    settings = ConsoleSection(
        listen="127.0.0.1:0",
        token_env=None,
        token_file=tmp_path / "token",
        users_file=users,
        poll_interval=0.5,
        history_step=1.0,
    )
    with ExitStack() as stack:
        cloud_router = stack.enter_context(ZenohRouter())
        base = uplink_config(cloud_router.endpoint, bootstrap, registry_url, suffix=suffix)
        uplinks = []
        for n, site in enumerate(sites, 1):  # uplink 1 takes site A's batches, uplink 2 site B's
            config = base.model_copy(
                update={
                    "id": f"uplink-{n}-{suffix}",
                    "console": settings,
                    "ingest": base.ingest.model_copy(update={"sites": [site]}),
                    "topics": base.topics.model_copy(update={"audit": f"e2e.audit.{suffix}"}),
                }
            )
            uplinks.append(stack.enter_context(Uplink(config, extensions=console_extensions(config))))
        cloud = Cloud(
            cloud_router.endpoint, bootstrap, registry_url, base.topics.registrations, base.topics.dead_letter
        )
        routers = []
        for i, (site, prefix) in enumerate(zip(sites, ("tb4_", "kb_"), strict=True)):
            router = stack.enter_context(ZenohRouter(connect=(cloud_router.endpoint,)))
            routers.append(router.endpoint)
            kind = prefix.rstrip("_")
            edge = edge_config(
                tmp_path / f"spool-{i}",
                router.endpoint,
                cloud,
                site=site,
                ros={"domain_id": domain, "message_paths": paths},
                robot_types={kind: {"match": f"/{prefix}*", "mappings": [IR_MAPPING]}},
            )
            sim = stack.enter_context(fleet(router.endpoint, domain, robots=2, rate=10.0, prefix=prefix))
            _admin, agent = console_agent(stack, edge, token)
            names = sim.names()
            wait_until(registered(agent, names), 15, message=f"{names} registered")
        consoles = []
        for uplink in uplinks:
            [console] = uplink.extensions
            assert isinstance(console, UplinkConsole)
            consoles.append(f"{console.url}/console/")
        yield Fleet2(
            sites=sites,
            consoles=(consoles[0], consoles[1]),
            uplinks=(uplinks[0], uplinks[1]),
            token=token,
            audit_topic=f"e2e.audit.{suffix}",
            suffix=suffix,
            bootstrap=bootstrap,
            routers=(routers[0], routers[1]),
            domain=domain,
        )


def registered(agent: EdgeAgent, names: list[str]) -> Callable[[], bool]:
    return lambda: sorted(agent.robots()) == names


@pytest.fixture(scope="module")
def fleet2(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Fleet2]:
    with two_sites(kafka_bootstrap, schema_registry_url, tmp_path_factory.mktemp("fleet2")) as running:
        yield running


def as_user(base: str, name: str) -> httpx.Client:
    return httpx.Client(base_url=base, auth=(name, PASSWORDS[name]), timeout=15)


def kafka_rate(view: dict[str, Any], topic: str) -> float:
    for node in view["graph"]["kafka"]:
        if node["id"] == f"k:{topic}":
            return float(node["rate"] or 0.0)
    return 0.0


def records(uplink: Uplink, site: str, topic: str | None = None) -> int:
    figures = uplink.delivery.figures(site)
    if figures is None:
        return 0
    return int(figures["records"] if topic is None else figures["topics"].get(topic, 0))


def test_each_site_alone_and_delivery_from_every_uplink(fleet2: Fleet2) -> None:
    site_a, site_b = fleet2.sites
    with as_user(fleet2.consoles[0], "sam") as first, as_user(fleet2.consoles[1], "sam") as second:

        def listed() -> bool:
            return {site_a, site_b} <= {s["site"] for s in first.get("api/sites").json()["sites"]}

        wait_until(listed, 10, message="both sites listed")

        views: dict[str, dict[str, Any]] = {}

        def acked_on_first() -> bool:
            for site in (site_a, site_b):
                views[site] = first.get(f"api/sites/{site}").json()
            return all(kafka_rate(views[s], "fleet.ir") > 0 for s in (site_a, site_b))

        wait_until(acked_on_first, 25, interval=0.5, message="Kafka acknowledged both sites' records")
        for site, own, other in ((site_a, "tb4_", "kb_"), (site_b, "kb_", "tb4_")):
            view = views[site]
            robots = [r["robot"] for r in view["robots"]]
            assert robots == [f"{own}01", f"{own}02"], robots
            shown = [n["id"] for n in view["graph"]["robots"]] + [n["id"] for n in view["graph"]["topics"]]
            assert not [i for i in shown if other in i or "fleetlink" in i], shown
            for robot in view["robots"]:
                assert robot["registered_at"] is not None
                assert robot["explicit"] is False  # it matched a robot type; nobody registered it by name
        # site B is uplink 2's alone, yet uplink 1's console shows what Kafka acknowledged for it
        assert fleet2.uplinks[0].delivery.figures(site_b) is None
        assert fleet2.uplinks[1].delivery.figures(site_a) is None
        for client in (first, second):
            pairs = list(zip(fleet2.uplinks, fleet2.sites, strict=True))
            before = sum(records(u, s) for u, s in pairs)
            ir_before = sum(records(u, s, "fleet.ir") for u, s in pairs)
            fleetwide = client.get("api/delivery").json()
            assert fleetwide["available"] is True
            assert fleetwide["uplink_count"] == 2
            assert {(u["site"], u["records"] > 0) for u in fleetwide["uplinks"]} == {
                (site_a, True),
                (site_b, True),
            }
            assert fleetwide["records"] >= before > 0
            assert fleetwide["topics"]["fleet.ir"]["acked"] >= ir_before > 0


def test_named_users_roles_and_the_audit_topic(fleet2: Fleet2) -> None:
    site_a = fleet2.sites[0]
    base = fleet2.consoles[0]
    wrong = httpx.get(f"{base}api/sites", auth=("lin", "not-the-password"), timeout=10)
    assert wrong.status_code == 401
    topic = f"console.imu.{fleet2.suffix}"
    form = {"name": "imu_fleet", "robot_type": "tb4", "from": "/{robot}/imu", "to": topic, "type": IMU}
    with as_user(base, "sam") as viewer, as_user(base, "lin") as operator:
        assert viewer.get("api/me").json() == {"user": "sam", "role": "viewer", "process": "uplink"}
        refused = viewer.post(f"api/sites/{site_a}/mappings", json=form, headers=CHANGE)
        assert refused.status_code == 403
        assert "operator" in refused.json()["error"]
        added = operator.post(f"api/sites/{site_a}/mappings", json=form, headers=CHANGE)
        assert added.status_code == 201, added.text
        assert "X-Fleetlink-Audit" not in added.headers
        removed = operator.delete(f"api/sites/{site_a}/mappings/imu_fleet", headers=CHANGE)
        assert removed.status_code == 200, removed.text
        assert viewer.get("api/audit").status_code == 403
    # the audit page needs an admin: the token's holder is one
    recent = httpx.get(f"{base}api/audit", headers={"Authorization": f"Bearer {fleet2.token}"}, timeout=10)
    assert [(r["user"], r["action"]) for r in recent.json()["records"][:2]] == [
        ("lin", "mapping.remove"),
        ("lin", "mapping.add"),
    ]
    consumer = Consumer(
        {
            "bootstrap.servers": fleet2.bootstrap,
            "group.id": f"audit-{uuid.uuid4().hex}",
            "auto.offset.reset": "earliest",
        }
    )
    try:
        consumer.subscribe([fleet2.audit_topic])
        found: list[dict[str, Any]] = []

        def two() -> bool:
            msg = consumer.poll(0.5)
            if msg is not None and msg.error() is None:
                assert msg.key() == b"lin"
                found.append(json.loads(msg.value()))
            return len(found) >= 2

        wait_until(two, 20, message="two audit records in Kafka")
    finally:
        consumer.close()
    assert [(r["user"], r["role"], r["action"], r["site"], r["target"], r["status"]) for r in found] == [
        ("lin", "operator", "mapping.add", site_a, "imu_fleet", 201),
        ("lin", "operator", "mapping.remove", site_a, "imu_fleet", 200),
    ]
    assert found[0]["detail"]["to"] == topic


IMU = "sensor_msgs/msg/Imu"


def test_robot_page_history_dead_letters_and_robot_types(fleet2: Fleet2) -> None:
    site_a = fleet2.sites[0]
    admin = {"Authorization": f"Bearer {fleet2.token}"}
    with as_user(fleet2.consoles[0], "sam") as viewer, as_user(fleet2.consoles[0], "lin") as operator:
        # the robot page: its registration and the latest value of each mapped topic, from its edge
        robot = viewer.get(f"api/sites/{site_a}/robots/tb4_01").json()
        assert (robot["registered"], robot["errors"]) == (True, {})
        assert robot["registration"]["robot_type"] == "tb4"
        latest = robot["latest"]["values"]["/tb4_01/ir_intensity"]
        assert latest["type"] == "irobot_create_msgs/msg/IrIntensityVector"
        assert isinstance(latest["value"]["readings"], list)
        assert robot["topics"][0] == {
            "topic": "/tb4_01/ir_intensity",
            "types": ["irobot_create_msgs/msg/IrIntensityVector"],
            "mappings": robot["topics"][0]["mappings"],
            "mapped": True,
        }
        # the charts: the console sampled the site every second
        history: dict[str, Any] = {}

        def sampled() -> bool:
            history.update(viewer.get(f"api/sites/{site_a}/history").json())
            points = history.get("site", {}).get("all", {})
            return len(points.get("t", [])) >= 2 and any(v for v in points.get("acked", []) if v)

        wait_until(sampled, 15, interval=0.5, message="two points of history with acknowledged records")
        assert history["available"] is True
        assert "ir" in history["mappings"]
        # the dead-letter browser reads the dead-letter topic (none yet: a healthy fleet)
        dead = viewer.get("api/dead-letters", params={"site": site_a}).json()
        assert (dead["available"], dead["records"]) == (True, [])
        assert viewer.get("api/dead-letters", params={"site": "no/such"}).status_code == 400
        # the robot-type editor: an admin's, with the admin API's validation
        body = {"match": "/tb4_*", "mappings": "- {name: ir, from: /{robot}/ir_intensity}"}
        assert (
            operator.put(f"api/sites/{site_a}/robot-types/tb4", json=body, headers=CHANGE).status_code == 403
        )
        url = f"{fleet2.consoles[0]}api/sites/{site_a}/robot-types/tb4"
        bad = httpx.put(url, json={**body, "mappings": "{not: a list}"}, headers=admin, timeout=15)
        assert bad.status_code == 422
        assert list(bad.json()["fields"]) == ["mappings"]
        refused = httpx.put(url, json=body, headers=admin, timeout=15)  # no "to", no "type"
        assert refused.status_code == 422, refused.text
        assert refused.json()["fields"]


def test_an_outage_shows_nothing_acknowledged_and_the_backlog(fleet2: Fleet2) -> None:
    """Last in the module: it stops the only uplink serving site B."""
    site_b = fleet2.sites[1]
    fleet2.uplinks[1].stop()
    with as_user(fleet2.consoles[0], "sam") as viewer:
        seen: list[dict[str, Any]] = []

        def stalled() -> bool:
            view = viewer.get(f"api/sites/{site_b}").json()
            seen.append(view)
            [node] = [n for n in view["graph"]["kafka"] if n["id"] == "k:fleet.ir"]
            backlog = view["graph"]["backlog"] or {}
            return node["rate"] == 0 and (backlog.get("records") or 0) > 0 and (node["mapped"] or 0) > 0

        wait_until(
            stalled, 20, interval=0.5, message="nothing acknowledged, a backlog, the mapping still running"
        )
        assert kafka_rate(seen[-1], "fleet.ir") == 0
