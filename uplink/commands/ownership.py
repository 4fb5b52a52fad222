"""Robots are owned: who may register or deregister a robot name (pure: no I/O, time passed in).

A robot belongs to the site that registered it. While it is registered there, no other site
can register it (nor deregister it), so commands for it go to that site alone. It leaves its
site in one of two ways:

* **liveliness lost + grace**: its site's edge deregisters it (the robot's liveliness tokens
  have been gone for the edge's ``registration.grace_period``); after the uplink's
  ``ownership.release_after`` more (default 0 s) any site may register it;
* **operator release**: a tombstone (null value) for the robot's key on the registrations
  topic forgets it at once (``fleetlink uplink release-robot``).

The rule decides at ingest, before the uplink writes a registration; reading the topic back
applies it again to every robot some site holds (``RobotDirectory``), so a conflicting record
that slipped in between two uplinks is ignored by every reader alike.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Owner:
    """The robot's current holder: its site, whether registered there, and since when (ms)."""

    site: str
    registered: bool
    since_ms: int


def claim_problem(
    owner: Owner | None, *, site: str, registered: bool, now_ms: int, release_after_ms: int
) -> str | None:
    """Why ``site`` may not (de)register the robot ``owner`` holds (None: it may)."""
    if owner is None or owner.site == site:
        return None if owner is not None or registered else f"site {site!r} deregisters a robot no site holds"
    problem = None
    if not registered:
        problem = f"the robot is site {owner.site!r}'s, not site {site!r}'s"
    elif owner.registered:
        problem = f"the robot is registered at site {owner.site!r}"
    elif now_ms < owner.since_ms + release_after_ms:
        problem = (
            f"the robot left site {owner.site!r} {(now_ms - owner.since_ms) / 1000:.1f} s ago and stays "
            f"its own for {release_after_ms / 1000:.0f} s (ownership.release_after)"
        )
    return problem
