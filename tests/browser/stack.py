"""A running fleetlink stack for the console tests: real Kafka and registry (session fixtures), a
cloud router with the uplink (fleet console on), a site router linked to it, an edge agent with
its admin API and console, and a simulated TurtleBot 4 fleet publishing through the site router.

    with console_stack(kafka_bootstrap, schema_registry_url, tmp_path) as stack:
        stack.edge_console      # http://127.0.0.1:P/console/   (the edge's site)
        stack.fleet_console     # http://127.0.0.1:Q/console/   (every site, over Zenoh)

Both consoles take the same token (``stack.token``), the one the edge's admin API takes.
"""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
from pydantic import SecretStr

from fleetlink.common.console_config import ConsoleSection
from fleetlink.console.edge import console_extension
from fleetlink.console.uplink import UplinkConsole, console_extensions
from fleetlink.edge.admin import EdgeAdmin
from fleetlink.edge.agent import EdgeAgent
from fleetlink.edge.config import EdgeConfig
from fleetlink.localstack.zenoh_router import ZenohRouter
from fleetlink.roswire.sim.fleet import Fleet
from fleetlink.schemas.bundled import bundled_message_paths
from fleetlink.uplink.service import Uplink
from tests.helpers import wait_until
from tests.integration.e2e_stack import Cloud, edge_config, unique_site, uplink_config
from tests.integration.test_admin_api import fleet, next_domain

IR_TYPE = "irobot_create_msgs/msg/IrIntensityVector"
IR_MAPPING = {
    "name": "ir",
    "from": "/{robot}/ir_intensity",
    "to": "fleet.ir",
    "type": IR_TYPE,
    "stages": [{"type": "throttle", "hz": 2}],
}


@dataclass
class Stack:
    site: str
    token: str
    edge_console: str
    fleet_console: str
    agent: EdgeAgent
    admin: EdgeAdmin
    uplink: Uplink
    sim: Fleet
    bootstrap: str
    registry_url: str
    suffix: str

    @property
    def bearer(self) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.token}"}

    def counters(self, mapping: str) -> dict[str, int]:
        counts: dict[str, int] = self.agent.snapshot().get("mappings", {}).get(mapping, {})
        return counts

    def client(self, base: str) -> httpx.Client:
        return httpx.Client(base_url=base, headers=self.bearer, timeout=15)


def console_agent(stack: ExitStack, edge: EdgeConfig, token: str) -> tuple[EdgeAdmin, EdgeAgent]:
    """An edge agent behind an admin API that serves the console's edge part; both end with ``stack``."""
    admin = EdgeAdmin(
        edge,
        token=SecretStr(token),
        listen="127.0.0.1:0",
        extensions=[console_extension(SecretStr(token), edge.edge_id)],
    )
    agent = stack.enter_context(EdgeAgent(admin.load(), stop_timeout_s=0.5))
    admin.attach(agent)
    stack.callback(admin.stop)
    return admin, agent


@contextmanager
def console_stack(
    bootstrap: str, registry_url: str, tmp_path: Path, *, robots: int = 2, rate: float = 10.0
) -> Iterator[Stack]:
    suffix = uuid.uuid4().hex[:8]
    token = f"console-{uuid.uuid4().hex}"
    token_file = tmp_path / "console-token"
    token_file.write_text(token + "\n")
    domain = next_domain()
    with ExitStack() as stack:
        cloud_router = stack.enter_context(ZenohRouter())
        settings = ConsoleSection(
            listen="127.0.0.1:0", token_env=None, token_file=token_file, poll_interval=0.5
        )
        config = uplink_config(cloud_router.endpoint, bootstrap, registry_url, suffix=suffix)
        config = config.model_copy(update={"console": settings})
        uplink = stack.enter_context(Uplink(config, extensions=console_extensions(config)))
        cloud = Cloud(
            cloud_router.endpoint,
            bootstrap,
            registry_url,
            config.topics.registrations,
            config.topics.dead_letter,
        )
        site_router = stack.enter_context(ZenohRouter(connect=(cloud_router.endpoint,)))
        site = unique_site()
        paths = [str(p) for p in bundled_message_paths()]
        ros: dict[str, Any] = {"domain_id": domain, "message_paths": paths}
        edge = edge_config(
            tmp_path / "spool",
            site_router.endpoint,
            cloud,
            site=site,
            ros=ros,
            robot_types={"tb4": {"match": "/tb4_*", "mappings": [IR_MAPPING]}},
        )
        sim = stack.enter_context(fleet(site_router.endpoint, domain, robots=robots, rate=rate))
        admin, agent = console_agent(stack, edge, token)
        names = sim.names()
        wait_until(lambda: sorted(agent.robots()) == names, 15, message=f"robots {names} registered")
        if len(uplink.extensions) != 1 or not isinstance(uplink.extensions[0], UplinkConsole):
            raise AssertionError("the uplink started without its console")
        console = uplink.extensions[0]
        yield Stack(
            site=site,
            token=token,
            edge_console=f"{admin.url}/console/",
            fleet_console=f"{console.url}/console/",
            agent=agent,
            admin=admin,
            uplink=uplink,
            sim=sim,
            bootstrap=bootstrap,
            registry_url=registry_url,
            suffix=suffix,
        )
