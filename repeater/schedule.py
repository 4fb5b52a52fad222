"""The repeater's scheduling core: which command to publish when, and when a command ends.

Pure and clock-injected: every method takes ``now`` (seconds since the epoch, the repeater's
wall clock) and returns what to publish and which status events happened; the caller does the
publishing and tells :meth:`Schedule.published` whether a subscriber was there to see it.

Rules, per *slot* (robot, ROS topic), at most one command is active:

* a command is **applied once** per (command id, robot); a repeat offer is a ``duplicate``;
* a command whose lease has ended is refused as ``expired`` (never published);
* a newer command (later issue time; the same time and a larger ``order``) **supersedes** the
  active one; an older one arriving late is itself ``superseded`` and never published;
* an active command is published at once, then every period, and at once again to each
  subscriber that appears on its topic (late joiner);
* it ends (``expired``) at its *deadline*: the earlier of its lease end and its receipt plus
  its lease length (a repeater whose clock runs behind still stops after one lease), or when
  the link to the uplink has been lost for longer than ``min(lease length, dead_man)``.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from enum import Enum

from fleetlink.wire.commands import Status


class Offer(Enum):
    """What became of a command offered to the schedule."""

    APPLIED = "applied"
    DUPLICATE = "duplicate"
    EXPIRED = "expired"
    SUPERSEDED = "superseded"


@dataclass(frozen=True, slots=True)
class Command:
    """What the schedule needs to know of a command (times in seconds since the epoch)."""

    command_id: str
    robot: str
    ros_topic: str
    issued_at: float
    lease_until: float
    period: float
    order: int = 0

    @property
    def lease(self) -> float:
        """The lease's length in seconds (its end minus the issue time)."""
        return self.lease_until - self.issued_at

    @property
    def slot(self) -> tuple[str, str]:
        """The (robot, ROS topic) the command is for: one command is active per slot."""
        return (self.robot, self.ros_topic)

    @property
    def ident(self) -> tuple[str, str]:
        """(command id, robot): a command is applied once per pair."""
        return (self.command_id, self.robot)

    def newer_than(self, other: Command) -> bool:
        """Whether this command supersedes ``other``: issued later, or at the same time with a larger
        ``order``."""
        return (self.issued_at, self.order) > (other.issued_at, other.order)


@dataclass(frozen=True, slots=True)
class Change:
    """A status event: ``command`` reached ``status`` at ``at``."""

    command: Command
    status: Status
    at: float
    detail: str = ""


@dataclass(frozen=True, slots=True)
class Publish:
    """Publish ``command`` now; ``reason`` is ``first``, ``repeat`` or ``late-joiner``."""

    command: Command
    reason: str


@dataclass
class _Active:
    command: Command
    received_at: float
    deadline: float
    next_due: float
    delivered: bool = False
    publishes: int = 0


@dataclass
class Outcome:
    """The answer to :meth:`Schedule.offer`: what became of the command, the status changes it caused and
    what to publish now."""

    offer: Offer
    changes: list[Change] = field(default_factory=list)
    publish: list[Publish] = field(default_factory=list)
    detail: str = ""


class Schedule:
    """The active command of each slot, when it is due and when it ends; which command ids it has seen.

    Not thread-safe: the repeater calls it under its lock.
    """

    def __init__(self, *, dead_man: float | None = None) -> None:
        if dead_man is not None and dead_man <= 0:
            raise ValueError(f"dead_man must be positive, got {dead_man}")
        self.dead_man = dead_man
        self._active: dict[tuple[str, str], _Active] = {}
        self._seen: dict[tuple[str, str], float] = {}  # (id, robot) -> lease end, kept until then
        self._link_lost_since: float | None = None

    # -- inputs ---------------------------------------------------------------------------

    def offer(
        self, command: Command, now: float, *, delivered: bool = False, received_at: float | None = None
    ) -> Outcome:
        """A command arrived (or was restored from the journal with ``received_at``)."""
        if command.ident in self._seen:
            return Outcome(Offer.DUPLICATE, detail="command id already applied")
        self._seen[command.ident] = command.lease_until
        received = now if received_at is None else received_at
        deadline = min(command.lease_until, received + command.lease)
        if now >= deadline:
            detail = (
                f"lease ended {now - command.lease_until:.3f} s before it could be applied"
                if now >= command.lease_until
                else "lease already used up since its receipt"
            )
            return Outcome(Offer.EXPIRED, [Change(command, "expired", now, detail)], detail=detail)
        current = self._active.get(command.slot)
        changes: list[Change] = []
        if current is not None:
            if current.command.newer_than(command):
                detail = f"a newer command {current.command.command_id} is already active"
                return Outcome(Offer.SUPERSEDED, [Change(command, "superseded", now, detail)], detail=detail)
            changes.append(Change(current.command, "superseded", now, f"superseded by {command.command_id}"))
        self._active[command.slot] = _Active(
            command, received, deadline, now + command.period, delivered=delivered
        )
        return Outcome(Offer.APPLIED, changes, [Publish(command, "first")])

    def remember(self, command: Command) -> None:
        """Mark a finished command as applied (restored from the journal): no resume, no replay."""
        self._seen[command.ident] = command.lease_until

    def published(self, command: Command, now: float, *, seen: bool) -> list[Change]:
        """The caller published ``command``; ``seen``: a subscriber was there. First seen -> delivered."""
        active = self._active.get(command.slot)
        if active is None or active.command.ident != command.ident:
            return []
        active.publishes += 1
        if seen and not active.delivered:
            active.delivered = True
            return [Change(command, "delivered", now, f"publish #{active.publishes}")]
        return []

    def subscriber_appeared(self, ros_topic: str, now: float) -> list[Publish]:
        """A subscriber appeared on ``ros_topic``: the active commands there go out at once."""
        return [
            Publish(a.command, "late-joiner")
            for a in self._active.values()
            if a.command.ros_topic == ros_topic and now < a.deadline
        ]

    def link_up(self) -> None:
        """The uplink answered: the dead-man stops counting."""
        self._link_lost_since = None

    def link_down(self, now: float) -> None:
        """The uplink did not answer at ``now``; the dead-man counts from the first such failure."""
        if self._link_lost_since is None:
            self._link_lost_since = now

    # -- time -----------------------------------------------------------------------------

    def tick(self, now: float) -> tuple[list[Publish], list[Change]]:
        """End what is over, then return the commands due for a repeat at ``now``."""
        changes = self._end_due(now)
        publish: list[Publish] = []
        for active in self._active.values():
            if active.next_due <= now:
                publish.append(Publish(active.command, "repeat"))
                active.next_due += active.command.period
                if active.next_due <= now:  # late (suspended, clock jump): no burst, resume the rhythm
                    active.next_due = now + active.command.period
        for ident in [i for i, until in self._seen.items() if until <= now]:
            del self._seen[ident]
        return publish, changes

    def next_wakeup(self) -> float | None:
        """When :meth:`tick` next has something to do (None: nothing active)."""
        times = [min(a.next_due, a.deadline) for a in self._active.values()]
        if self._link_lost_since is not None:
            times += [self._link_lost_since + self._dead_man_limit(a.command) for a in self._active.values()]
        return min(times, default=None)

    def _dead_man_limit(self, command: Command) -> float:
        return command.lease if self.dead_man is None else min(command.lease, self.dead_man)

    def _end_due(self, now: float) -> list[Change]:
        changes: list[Change] = []
        lost = self._link_lost_since
        for slot, active in list(self._active.items()):
            command = active.command
            said = "after delivery" if active.delivered else "never seen by a subscriber"
            if now >= active.deadline:
                changes.append(Change(command, "expired", now, f"lease ended ({said})"))
            elif lost is not None and now - lost >= self._dead_man_limit(command):
                detail = f"dead-man: no contact with the uplink for {now - lost:.1f} s ({said})"
                changes.append(Change(command, "expired", now, detail))
            else:
                continue
            del self._active[slot]
        return changes

    # -- views ----------------------------------------------------------------------------

    def active(self) -> list[Command]:
        """The commands active now, one per slot."""
        return [a.command for a in self._active.values()]

    def is_active(self, command: Command) -> bool:
        """Whether ``command`` is still the active command of its slot."""
        current = self._active.get(command.slot)
        return current is not None and current.command.ident == command.ident

    def delivered(self, command: Command) -> bool:
        """Whether ``command`` is active and a subscriber has seen it."""
        current = self._active.get(command.slot)
        return current is not None and current.command.ident == command.ident and current.delivered

    def topics(self) -> set[str]:
        """The ROS topics with an active command."""
        return {a.command.ros_topic for a in self._active.values()}

    def seen(self) -> Iterable[tuple[str, str]]:
        """The (command id, robot) pairs offered so far, each remembered until its lease ends."""
        return self._seen.keys()

    @property
    def link_lost_since(self) -> float | None:
        """When the link to the uplink was lost (seconds since the epoch; ``None``: it is up)."""
        return self._link_lost_since
