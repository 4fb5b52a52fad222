"""What the edge remembers about each robot's registrations (pure; thread-safe).

``RobotLog.record(change)`` is called for every registration and deregistration the agent
applies. ``details()`` answers, per robot registered now, when it registered and how
(discovered from its namespace, or explicitly on the register topic); ``history(robot)`` the
robot's last ``max_events`` changes, newest last. Both go into the agent's snapshot
(``robot_details``, ``robot_history``), which the admin API and the console read.
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Any

from fleetlink.edge.runtime.registration import RobotChange


class RobotLog:
    """Remembers, per robot, when and how it registered and its last ``max_events`` changes (for at most
    ``max_robots`` robots); thread-safe."""

    def __init__(self, *, max_events: int = 20, max_robots: int = 10_000) -> None:
        self.max_events = max_events
        self.max_robots = max_robots
        self._since: dict[str, tuple[int, bool]] = {}
        self._history: dict[str, deque[dict[str, Any]]] = {}
        self._lock = threading.Lock()

    def record(self, change: RobotChange) -> None:
        """Note one registration or deregistration; beyond ``max_robots`` robots, the one heard of longest
        ago is forgotten."""
        entry = {
            "event": change.event,
            "robot_type": change.robot_type,
            "reason": change.reason,
            "at_ms": change.timestamp_ms,
        }
        with self._lock:
            if change.registered:
                self._since[change.robot] = (change.timestamp_ms, change.reason == "explicit")
            else:
                self._since.pop(change.robot, None)
            events = self._history.get(change.robot)
            if events is None:
                if len(self._history) >= self.max_robots:  # forget the robot heard of longest ago
                    oldest = min(self._history, key=lambda r: self._history[r][-1]["at_ms"])
                    del self._history[oldest]
                events = self._history[change.robot] = deque(maxlen=self.max_events)
            events.append(entry)

    def details(self) -> dict[str, dict[str, Any]]:
        """``{robot: {"registered_at_ms", "explicit", "state"}}`` for robots registered now."""
        with self._lock:
            return {
                robot: {"registered_at_ms": at_ms, "explicit": explicit, "state": "registered"}
                for robot, (at_ms, explicit) in self._since.items()
            }

    def history(self) -> dict[str, list[dict[str, Any]]]:
        """``{robot: [{"event", "robot_type", "reason", "at_ms"}, ...]}``, oldest first."""
        with self._lock:
            return {robot: list(events) for robot, events in self._history.items()}
