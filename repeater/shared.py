"""What the repeater's jobs share: the schedule, the journal, the converted commands, the
publishers and the status link, guarded by one lock (every publish happens under it)."""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from fleetlink.repeater.publishers import Publishers
from fleetlink.repeater.schedule import Command, Publish, Schedule
from fleetlink.repeater.state import CommandStore, Ident
from fleetlink.repeater.status_link import StatusLink
from fleetlink.wire.commands import CommandEnvelope


@dataclass
class RepeaterStats:
    """Running totals of what the repeater did with commands, read by the metrics and the health."""

    applied: int = 0
    duplicates: int = 0
    expired_on_arrival: int = 0
    superseded_on_arrival: int = 0
    rejected: int = 0
    need_schema: int = 0
    malformed: int = 0
    forged: int = 0
    """Commands refused unread: not signed by a trusted key for this site."""
    publishes: int = 0
    late_joiner_publishes: int = 0
    publish_errors: int = 0
    by_topic: Counter[str] = field(default_factory=Counter)
    """Publishes per ROS topic."""


def to_command(env: CommandEnvelope) -> Command:
    """What the schedule needs of a command envelope (its times in seconds)."""
    return Command(
        env.command_id,
        env.robot,
        env.ros_topic,
        env.issued_at_ms / 1000,
        env.lease_until_ms / 1000,
        env.period_ms / 1000,
        env.order,
    )


@dataclass(eq=False)
class Shared:
    """The repeater's state; everything but ``poke`` is touched under ``lock``."""

    site: str
    id: str
    clock: Callable[[], float]
    schedule: Schedule
    store: CommandStore
    stats: RepeaterStats = field(default_factory=RepeaterStats)
    lock: threading.RLock = field(default_factory=threading.RLock)
    poke: threading.Event = field(default_factory=threading.Event)
    """Wakes the publish loop (set without taking the lock)."""
    cdr: dict[Ident, tuple[CommandEnvelope, bytes]] = field(default_factory=dict)
    """Each active command converted once, kept for its repeats."""
    initial: list[Publish] = field(default_factory=list)
    """Publishes due before the publishers exist (restored commands); the loop takes them first."""
    publishers: Publishers | None = None
    link: StatusLink | None = None
