"""A fleet's Zenoh topology on loopback for the router-config tests: cloud, edges, clients.

Routers are opened from the shipped templates in ``deploy/zenoh/`` (rendered by
fleetlink.common.zenoh_configs); clients (robots, edge agents, the uplink) are small client-mode
sessions. Everything binds 127.0.0.1 on free ports.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import zenoh

from fleetlink.common.certs import CLOUD_NAME, UPLINK_NAME, CertBundle, edge_name, generate_bundle
from fleetlink.common.zenoh_configs import render_router_config
from tests.helpers import free_port

DEPLOY = Path(__file__).resolve().parents[2] / "deploy" / "zenoh"
SITES = ("site-a", "site-b")


def make_bundle(directory: Path, sites: Sequence[str] = SITES) -> CertBundle:
    return generate_bundle(directory, now=datetime.now(UTC), sites=sites)


def client_config(
    endpoint: str,
    *,
    bundle: CertBundle | None = None,
    identity: str | None = None,
    user: str | None = None,
    password: str | None = None,
) -> zenoh.Config:
    """A client-mode session config; TLS material from ``bundle`` (``identity`` = cert name)."""
    tls: dict[str, object] = {}
    if bundle is not None:
        tls["root_ca_certificate"] = str(bundle.ca_certificate)
    if bundle is not None and identity is not None:
        files = bundle[identity]
        tls |= {
            "enable_mtls": True,
            "connect_certificate": str(files.certificate),
            "connect_private_key": str(files.key),
        }
    conf: dict[str, object] = {
        "mode": "client",
        "connect": {"endpoints": [endpoint]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {"link": {"tls": tls}},
    }
    if user is not None:
        conf["transport"] = {"link": {"tls": tls}, "auth": {"usrpwd": {"user": user, "password": password}}}
    return zenoh.Config.from_json5(json.dumps(conf))


@contextmanager
def opened(conf: zenoh.Config) -> Iterator[zenoh.Session]:
    session = zenoh.open(conf)
    try:
        yield session
    finally:
        session.close()


class Collector:
    """Thread-safe record of samples (key, payload) delivered to a subscriber callback."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._items: list[tuple[str, bytes]] = []

    def __call__(self, sample: zenoh.Sample) -> None:
        with self._lock:
            self._items.append((str(sample.key_expr), sample.payload.to_bytes()))

    @property
    def items(self) -> list[tuple[str, bytes]]:
        with self._lock:
            return list(self._items)

    def key_exprs(self) -> list[str]:
        return [key for key, _ in self.items]

    def count(self, prefix: str) -> int:
        return sum(1 for key in self.key_exprs() if key.startswith(prefix))


@dataclass(frozen=True)
class Cloud:
    session: zenoh.Session
    endpoint: str


@dataclass(frozen=True)
class Edge:
    session: zenoh.Session
    site: str
    endpoint: str  # where the site's robots and agent connect (tcp)


@contextmanager
def tls_cloud(
    bundle: CertBundle,
    sites: Sequence[str] = SITES,
    *,
    raw_from: Mapping[str, Sequence[str]] | None = None,
    acl: bool = True,
) -> Iterator[Cloud]:
    endpoint = f"tls/127.0.0.1:{free_port()}"
    conf = render_router_config(
        DEPLOY / "cloud-router.json5",
        listen=[endpoint],
        cert_dir=bundle.directory,
        sites=sites,
        raw_from=raw_from,
    )
    if not acl:
        conf.insert_json5("access_control/enabled", "false")
    with opened(conf) as session:
        yield Cloud(session, endpoint)


@contextmanager
def tls_edge(
    bundle: CertBundle, site: str, cloud_endpoint: str, *, raw_to_cloud: Sequence[str] = ()
) -> Iterator[Edge]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    conf = render_router_config(
        DEPLOY / "edge-router.json5",
        site=site,
        listen=[endpoint],
        connect=[cloud_endpoint],
        cert_dir=bundle.directory,
        raw_to_cloud=raw_to_cloud,
    )
    with opened(conf) as session:
        yield Edge(session, site, endpoint)


def uplink_config(bundle: CertBundle, cloud_endpoint: str) -> zenoh.Config:
    return client_config(cloud_endpoint, bundle=bundle, identity=UPLINK_NAME)


def edge_identity_config(bundle: CertBundle, site: str, cloud_endpoint: str) -> zenoh.Config:
    """A client holding the site's edge certificate, connected straight to the cloud."""
    return client_config(cloud_endpoint, bundle=bundle, identity=edge_name(site))


def routers_connected(session: zenoh.Session) -> int:
    return len(list(session.info.routers_zid()))


__all__ = [
    "CLOUD_NAME",
    "DEPLOY",
    "SITES",
    "Cloud",
    "Collector",
    "Edge",
    "client_config",
    "edge_identity_config",
    "make_bundle",
    "opened",
    "routers_connected",
    "tls_cloud",
    "tls_edge",
    "uplink_config",
]
