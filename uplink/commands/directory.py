"""Where each robot is: robot -> site, from the registration events (pure state).

The uplink writes a registration event per change to the compacted topic ``fleetlink.robots``
(key = robot; value: Avro with at least ``robot``, ``site`` and ``event`` = ``registered`` |
``deregistered``), after checking it came from the robot's owner (``ownership``). A registered
robot is addressed at its site. A deregistered robot keeps its *last known* site (it is most
likely to come back there, and a command's lease covers a robot that rejoins late) but is no
longer part of a broadcast. A tombstone (null value) forgets the robot: its commands go to
every site again, and any site may register it (an operator's release).

Reading the topic applies the ownership rule again: a record from another site while the
robot's holder still holds it is ignored (``conflicts``), so every uplink agrees on the owner
even if two uplinks accepted conflicting claims within moments of each other.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from typing import Any

from fleetlink.uplink.commands.ownership import Owner, claim_problem


class RobotDirectory:
    """Thread-safe: the registrations reader and the ingest write, the command router reads."""

    def __init__(self, *, release_after_ms: int = 0) -> None:
        self._robots: dict[str, Owner] = {}
        self._lock = threading.Lock()
        self.release_after_ms = release_after_ms
        self.events = 0
        self.ignored = 0
        self.conflicts = 0

    def apply(self, key: str | None, value: Mapping[str, Any] | None, timestamp_ms: int = 0) -> bool:
        """Apply one registration record (``value`` None: tombstone); False if it was unusable
        or came from a site that does not hold the robot."""
        if value is None:
            if key:
                with self._lock:
                    self._robots.pop(key, None)
                self.events += 1
                return True
            self.ignored += 1
            return False
        robot = value.get("robot") or key
        site = value.get("site")
        event = value.get("event", "registered")
        if (
            not isinstance(robot, str)
            or not robot
            or not isinstance(site, str)
            or not site
            or event not in ("registered", "deregistered")
        ):
            self.ignored += 1
            return False
        registered = event == "registered"
        with self._lock:
            owner = self._robots.get(robot)
            if owner is not None and claim_problem(
                owner,
                site=site,
                registered=registered,
                now_ms=timestamp_ms,
                release_after_ms=self.release_after_ms,
            ):
                self.conflicts += 1
                return False
            self._robots[robot] = Owner(site, registered, timestamp_ms)
        self.events += 1
        return True

    def claim(self, robot: str, site: str, *, registered: bool, now_ms: int) -> str | None:
        """Check and apply, atomically, ``site`` (de)registering ``robot`` (the ingest's rule);
        returns why it may not (then nothing changes)."""
        with self._lock:
            problem = claim_problem(
                self._robots.get(robot),
                site=site,
                registered=registered,
                now_ms=now_ms,
                release_after_ms=self.release_after_ms,
            )
            if problem is None:
                self._robots[robot] = Owner(site, registered, now_ms)
        return problem

    def owner(self, robot: str) -> Owner | None:
        """The site holding ``robot``, whether it is registered there and since when (None: no site holds
        it)."""
        with self._lock:
            return self._robots.get(robot)

    def site_of(self, robot: str) -> str | None:
        """The site where ``robot`` is registered or was last known (None: unknown, so every site)."""
        with self._lock:
            entry = self._robots.get(robot)
        return None if entry is None else entry.site

    def registered(self) -> list[str]:
        """Robots currently registered (the targets of a broadcast)."""
        with self._lock:
            return sorted(r for r, e in self._robots.items() if e.registered)

    def sites(self) -> list[str]:
        """Every site that holds or last held a robot, sorted."""
        with self._lock:
            return sorted({e.site for e in self._robots.values()})

    def __len__(self) -> int:
        with self._lock:
            return len(self._robots)
