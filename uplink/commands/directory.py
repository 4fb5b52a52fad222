"""Where each robot is: robot -> site, from the registration events (pure state).

The edge agents write a registration event per change to the compacted topic
``fleetlink.robots`` (key = robot; value: Avro with at least ``robot``, ``site`` and
``event`` = ``registered`` | ``deregistered``). A registered robot is addressed at its site.
A deregistered robot keeps its *last known* site (it is most likely to come back there, and
a command's lease covers a robot that rejoins late) but is no longer part of a broadcast. A
tombstone (null value) forgets the robot: its commands go to every site again.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True, slots=True)
class RobotEntry:
    site: str
    registered: bool


class RobotDirectory:
    """Thread-safe: the registrations reader writes, the command router reads."""

    def __init__(self) -> None:
        self._robots: dict[str, RobotEntry] = {}
        self._lock = threading.Lock()
        self.events = 0
        self.ignored = 0

    def apply(self, key: str | None, value: Mapping[str, Any] | None) -> bool:
        """Apply one registration record (``value`` None: tombstone); False if it was unusable."""
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
        with self._lock:
            self._robots[robot] = RobotEntry(site, event == "registered")
        self.events += 1
        return True

    def site_of(self, robot: str) -> str | None:
        with self._lock:
            entry = self._robots.get(robot)
        return None if entry is None else entry.site

    def registered(self) -> list[str]:
        """Robots currently registered (the targets of a broadcast)."""
        with self._lock:
            return sorted(r for r, e in self._robots.items() if e.registered)

    def sites(self) -> list[str]:
        with self._lock:
            return sorted({e.site for e in self._robots.values()})

    def __len__(self) -> int:
        with self._lock:
            return len(self._robots)
