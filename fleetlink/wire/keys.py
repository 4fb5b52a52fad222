"""Key expressions: every key of a site lives under ``fleetlink/<site>/``."""

from __future__ import annotations

from fleetlink.common.names import key_chunk_problem, key_path_problem
from fleetlink.wire.errors import WireError

ROOT = "fleetlink"


def check_key_name(name: str, what: str = "name") -> str:
    """A robot as key-expression chunks: letters, digits, '_', '.', '-' (a robot may span
    several '/'-separated chunks). No wildcards, no empty chunks."""
    problem = key_path_problem(name)
    if problem is not None:
        raise WireError(f"{what} {name!r} {problem}")
    return name


def check_key_chunk(name: str, what: str = "name") -> str:
    """A site, edge id or command name: one key chunk (``common.names.key_chunk_problem``)."""
    problem = key_chunk_problem(name)
    if problem is not None:
        raise WireError(f"{what} {name!r} {problem}")
    return name


def site_prefix(site: str) -> str:
    """``fleetlink/<site>``: every key of a site lives under it, so routers and ACLs scope a site."""
    return f"{ROOT}/{check_key_chunk(site, 'site')}"


def ingest_key(site: str, edge_id: str) -> str:
    """Where an edge sends its batches: ``fleetlink/<site>/ingest/<edge_id>``."""
    return f"{site_prefix(site)}/ingest/{check_key_chunk(edge_id, 'edge_id')}"


VIA = "via"
"""The chunk after an ingest key that names the uplink a batch is for (``.../via/<uplink id>``)."""


def via_key(ingest: str, uplink_id: str) -> str:
    """An ingest key addressed to one uplink: ``fleetlink/<site>/ingest/<edge_id>/via/<uplink id>``
    (``*``: every uplink serving the key, the edge's probe)."""
    return f"{ingest}/{VIA}/{uplink_id}"


def ack_key(site: str, edge_id: str) -> str:
    """Where acks for one edge go when sent as puts: ``fleetlink/<site>/ack/<edge_id>``."""
    return f"{site_prefix(site)}/ack/{check_key_chunk(edge_id, 'edge_id')}"


def command_key(site: str, robot: str, command: str) -> str:
    """Commands for one robot: ``fleetlink/<site>/command/<robot>/<command>``."""
    robot = check_key_name(robot, "robot")
    return f"{site_prefix(site)}/command/{robot}/{check_key_chunk(command, 'command')}"


def events_key(site: str) -> str:
    """Robot registration events of a site: ``fleetlink/<site>/events``."""
    return f"{site_prefix(site)}/events"


def admin_key(site: str) -> str:
    """Everything administrative of a site: ``fleetlink/<site>/admin/**``."""
    return f"{site_prefix(site)}/admin/**"


def delivery_key(site: str, uplink_id: str) -> str:
    """Where an uplink answers what it delivered to Kafka for a site:
    ``fleetlink/<site>/delivery/<uplink_id>`` (under the site's prefix, so the per-site ACLs let a
    site read its own figures and no other's; a query on ``fleetlink/<site>/delivery/*`` gets one
    answer per uplink)."""
    return f"{site_prefix(site)}/delivery/{check_key_chunk(uplink_id, 'uplink id')}"
