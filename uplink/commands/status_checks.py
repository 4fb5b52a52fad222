"""Status batches from repeaters, checked against the key they arrived on (pure).

A repeater sends status batches on ``fleetlink/<site>/command-status/<repeater>``; routers let
a site query only under its own keys, so the key's site is the sender's. A batch naming another
site is refused whole; events about a robot another site holds are dropped (the site may not
speak for it); every kept event carries the key's site, whatever it said.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

from fleetlink.uplink.commands.ownership import Owner
from fleetlink.wire.commands import StatusBatch, StatusEvent


@dataclass(frozen=True, slots=True)
class CheckedStatus:
    """A status batch after the checks: the events to write, how many were dropped, and why it is
    refused whole, if it is."""

    events: list[StatusEvent]
    dropped: int
    problem: str | None = None
    """Why the whole batch is refused (then ``events`` is empty)."""


def site_of_status_key(key: str) -> str | None:
    """The site of a ``fleetlink/<site>/command-status/<repeater>`` key, or None for any other key."""
    parts = key.split("/")
    if len(parts) == 4 and parts[0] == "fleetlink" and parts[2] == "command-status":
        return parts[1]
    return None


def check_status(key: str, batch: StatusBatch, owner_of: Callable[[str], Owner | None]) -> CheckedStatus:
    """Check a status batch against ``key``: refuse it when it names another site, drop events about robots
    another site holds, and give the rest the key's site."""
    site = site_of_status_key(key)
    if site is None:
        return CheckedStatus([], 0, f"{key!r} is not a status key")
    if batch.site != site:
        return CheckedStatus([], 0, f"the batch says site {batch.site!r} but arrived on site {site!r}'s key")
    kept: list[StatusEvent] = []
    for event in batch.events:
        owner = owner_of(event.robot)
        if owner is not None and owner.site != site:
            continue
        kept.append(event if event.site == site else replace(event, site=site))
    return CheckedStatus(kept, len(batch.events) - len(kept))
