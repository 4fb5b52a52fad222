"""What the demo tells and checks, kept apart from the processes (pure, clock injected)."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any


def led_colour(value: dict[str, Any] | None) -> str:
    """``red`` / ``green`` / ``off`` / ``mixed`` for a LightringLeds record (as decoded from Avro)."""
    if not value:
        return "unknown"
    names = set()
    for led in value.get("leds", []):
        rgb = (led.get("red", 0), led.get("green", 0), led.get("blue", 0))
        names.add({(255, 0, 0): "red", (0, 255, 0): "green", (0, 0, 0): "off"}.get(rgb, "other"))
    return names.pop() if len(names) == 1 else "mixed"


@dataclass
class Story:
    """Everything observed, for the running commentary and the closing summary."""

    started_at: float
    commands: dict[str, list[str]] = field(default_factory=lambda: defaultdict(list))
    leds: dict[str, list[tuple[float, str]]] = field(default_factory=lambda: defaultdict(list))
    registered: dict[str, float] = field(default_factory=dict)
    faults: dict[str, float] = field(default_factory=dict)
    heals: dict[str, float] = field(default_factory=dict)
    latencies: dict[str, float] = field(default_factory=dict)

    def at(self, now: float) -> str:
        """The time since the start as a line prefix, e.g. ``[  12.3s]``."""
        return f"[{now - self.started_at:6.1f}s]"

    def on_command(self, robot: str, colour: str) -> None:
        """Record a light-ring command seen in Kafka for ``robot``."""
        self.commands[robot].append(colour)

    def on_led(self, robot: str, colour: str, now: float) -> bool:
        """Record a light-ring change; True when it is a change worth telling."""
        history = self.leds[robot]
        if history and history[-1][1] == colour:
            return False
        history.append((now, colour))
        if colour == "red" and robot in self.faults and f"{robot}:red" not in self.latencies:
            self.latencies[f"{robot}:red"] = now - self.faults[robot]
        if colour == "green" and robot in self.heals and f"{robot}:green" not in self.latencies:
            self.latencies[f"{robot}:green"] = now - self.heals[robot]
        return True

    def led_now(self, robot: str) -> str | None:
        """``robot``'s current light-ring colour, or None before any was seen."""
        history = self.leds.get(robot)
        return history[-1][1] if history else None

    def summary(self, faulted: str, healthy: list[str], joined: str | None) -> dict[str, Any]:
        """The closing summary: whether the loop closed (``faulted`` got red then green, the others no
        command, ``joined`` registered), the commands seen and the light-ring latencies."""
        loop_closed = (
            self.commands.get(faulted) == ["red", "green"]
            and all(not self.commands.get(r) for r in healthy)
            and (joined is None or joined in self.registered)
        )
        return {
            "loop_closed": loop_closed,
            "faulted_robot": faulted,
            "commands": {robot: list(c) for robot, c in self.commands.items()},
            "healthy_robots_without_commands": [r for r in healthy if not self.commands.get(r)],
            "registered": sorted(self.registered),
            "joined_mid_run": joined,
            "fault_to_red_led_s": self.latencies.get(f"{faulted}:red"),
            "heal_to_green_led_s": self.latencies.get(f"{faulted}:green"),
        }
