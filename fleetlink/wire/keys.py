"""Key expressions: every key of a site lives under ``fleetlink/<site>/``."""

from __future__ import annotations

import re

from fleetlink.wire.errors import WireError

ROOT = "fleetlink"
_KEY_CHUNK = re.compile(r"[A-Za-z0-9_.-]+(?:/[A-Za-z0-9_.-]+)*")


def check_key_name(name: str, what: str = "name") -> str:
    """A site, edge id or robot as key-expression chunks: letters, digits, '_', '.', '-'
    (robots may span several '/'-separated chunks). No wildcards, no empty chunks."""
    if _KEY_CHUNK.fullmatch(name) is None:
        raise WireError(
            f"{what} {name!r} cannot be used in a key expression: use letters, digits, "
            "'_', '.', '-' (no wildcards, no empty chunks)"
        )
    return name


def site_prefix(site: str) -> str:
    """``fleetlink/<site>``: every key of a site lives under it, so routers and ACLs scope a site."""
    if "/" in site:
        raise WireError(f"site {site!r} must be a single key chunk")
    return f"{ROOT}/{check_key_name(site, 'site')}"


def ingest_key(site: str, edge_id: str) -> str:
    """Where an edge sends its batches: ``fleetlink/<site>/ingest/<edge_id>``."""
    if "/" in edge_id:
        raise WireError(f"edge_id {edge_id!r} must be a single key chunk")
    return f"{site_prefix(site)}/ingest/{check_key_name(edge_id, 'edge_id')}"


def ack_key(site: str, edge_id: str) -> str:
    """Where acks for one edge go when sent as puts: ``fleetlink/<site>/ack/<edge_id>``."""
    if "/" in edge_id:
        raise WireError(f"edge_id {edge_id!r} must be a single key chunk")
    return f"{site_prefix(site)}/ack/{check_key_name(edge_id, 'edge_id')}"


def command_key(site: str, robot: str, command: str) -> str:
    """Commands for one robot: ``fleetlink/<site>/command/<robot>/<command>``."""
    if "/" in command:
        raise WireError(f"command {command!r} must be a single key chunk")
    robot = check_key_name(robot, "robot")
    return f"{site_prefix(site)}/command/{robot}/{check_key_name(command, 'command')}"


def events_key(site: str) -> str:
    """Robot registration events of a site: ``fleetlink/<site>/events``."""
    return f"{site_prefix(site)}/events"


def admin_key(site: str) -> str:
    """Everything administrative of a site: ``fleetlink/<site>/admin/**``."""
    return f"{site_prefix(site)}/admin/**"
