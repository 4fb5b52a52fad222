"""The repeater's scheduling core, as timelines: offers, ticks, late joiners, link changes."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from fleetlink.repeater.schedule import Command, Offer, Schedule

T0 = 1_700_000_000.0


def cmd(
    cid: str = "c1",
    robot: str = "tb4_01",
    topic: str = "/tb4_01/cmd_lightring",
    *,
    issued: float = 0.0,
    lease: float = 10.0,
    period: float = 1.0,
    order: int = 0,
) -> Command:
    return Command(cid, robot, topic, T0 + issued, T0 + issued + lease, period, order)


@dataclass(frozen=True)
class Step:
    at: float  # seconds after T0
    action: str  # offer:<name> | tick | join:<topic> | up | down
    expect: tuple[str, ...] = ()  # "pub:<id>:<reason>", "<status>:<id>", "offer:<result>"


def run(steps: list[Step], commands: dict[str, Command], dead_man: float | None = None) -> None:
    schedule = Schedule(dead_man=dead_man)
    for step in steps:
        now = T0 + step.at
        got: list[str] = []
        kind, _, arg = step.action.partition(":")
        if kind == "offer":
            outcome = schedule.offer(commands[arg], now)
            got.append(f"offer:{outcome.offer.value}")
            got += [f"{c.status}:{c.command.command_id}" for c in outcome.changes]
            got += [f"pub:{p.command.command_id}:{p.reason}" for p in outcome.publish]
        elif kind == "tick":
            publish, changes = schedule.tick(now)
            got += [f"{c.status}:{c.command.command_id}" for c in changes]
            got += [f"pub:{p.command.command_id}:{p.reason}" for p in publish]
        elif kind == "join":
            got += [f"pub:{p.command.command_id}:{p.reason}" for p in schedule.subscriber_appeared(arg, now)]
        elif kind == "up":
            schedule.link_up()
        elif kind == "down":
            schedule.link_down(now)
        else:
            raise ValueError(step.action)
        assert tuple(got) == step.expect, f"at {step.at}: {step.action}"


CASES: dict[str, tuple[list[Step], dict[str, Command], float | None]] = {
    "published at once, then every period, until the lease ends": (
        [
            Step(0.0, "offer:a", ("offer:applied", "pub:a:first")),
            Step(0.5, "tick"),
            Step(1.0, "tick", ("pub:a:repeat",)),
            Step(1.1, "tick"),
            Step(2.0, "tick", ("pub:a:repeat",)),
            Step(9.99, "tick", ("pub:a:repeat",)),  # late tick: one repeat, no burst
            Step(10.0, "tick", ("expired:a",)),
            Step(11.0, "tick"),
        ],
        {"a": cmd("a")},
        None,
    ),
    "a re-delivered command id is a duplicate, even after it ended": (
        [
            Step(0.0, "offer:a", ("offer:applied", "pub:a:first")),
            Step(0.2, "offer:a", ("offer:duplicate",)),
            Step(1.0, "offer:b", ("offer:applied", "superseded:a", "pub:b:first")),
            Step(1.5, "offer:a", ("offer:duplicate",)),
        ],
        {"a": cmd("a"), "b": cmd("b", issued=1.0)},
        None,
    ),
    "a newer command supersedes; the old one is no longer repeated": (
        [
            Step(0.0, "offer:a", ("offer:applied", "pub:a:first")),
            Step(1.0, "tick", ("pub:a:repeat",)),
            Step(1.5, "offer:b", ("offer:applied", "superseded:a", "pub:b:first")),
            Step(2.0, "tick"),
            Step(2.5, "tick", ("pub:b:repeat",)),
        ],
        {"a": cmd("a"), "b": cmd("b", issued=1.5)},
        None,
    ),
    "an older command arriving late is superseded on arrival, never published": (
        [
            Step(2.0, "offer:new", ("offer:applied", "pub:new:first")),
            Step(2.1, "offer:old", ("offer:superseded", "superseded:old")),
            Step(3.0, "tick", ("pub:new:repeat",)),
        ],
        {"new": cmd("new", issued=2.0), "old": cmd("old", issued=1.0)},
        None,
    ),
    "same timestamp: the larger order (Kafka offset) wins in either arrival order": (
        [
            Step(0.0, "offer:o8", ("offer:applied", "pub:o8:first")),
            Step(0.1, "offer:o7", ("offer:superseded", "superseded:o7")),
            Step(0.2, "offer:o9", ("offer:applied", "superseded:o8", "pub:o9:first")),
        ],
        {f"o{n}": cmd(f"o{n}", order=n) for n in (7, 8, 9)},
        None,
    ),
    "other robots and topics are separate slots": (
        [
            Step(0.0, "offer:a", ("offer:applied", "pub:a:first")),
            Step(0.0, "offer:b", ("offer:applied", "pub:b:first")),
            Step(0.0, "offer:c", ("offer:applied", "pub:c:first")),
            Step(1.0, "tick", ("pub:a:repeat", "pub:b:repeat", "pub:c:repeat")),
        ],
        {
            "a": cmd("a"),
            "b": cmd("b", robot="tb4_02", topic="/tb4_02/cmd_lightring"),
            "c": cmd("c", topic="/tb4_01/other"),
        },
        None,
    ),
    "a command whose lease already ended is refused as expired": (
        [
            Step(10.0, "offer:a", ("offer:expired", "expired:a")),
            Step(10.5, "offer:a", ("offer:duplicate",)),
            Step(11.0, "tick"),
        ],
        {"a": cmd("a")},
        None,
    ),
    "late joiner: the active command at once, on its topic only, not after the lease": (
        [
            Step(0.0, "offer:a", ("offer:applied", "pub:a:first")),
            Step(3.3, "join:/tb4_01/cmd_lightring", ("pub:a:late-joiner",)),
            Step(3.4, "join:/tb4_02/cmd_lightring"),
            Step(10.0, "tick", ("expired:a",)),
            Step(10.1, "join:/tb4_01/cmd_lightring"),
        ],
        {"a": cmd("a", period=60.0)},
        None,
    ),
    "no cap: repeats go on through a lost link, and end with the lease": (
        [
            Step(0.0, "offer:a", ("offer:applied", "pub:a:first")),
            Step(1.0, "down"),
            Step(2.0, "tick", ("pub:a:repeat",)),
            Step(4.9, "tick", ("pub:a:repeat",)),
            Step(5.0, "tick", ("expired:a",)),
        ],
        {"a": cmd("a", lease=5.0, period=2.0)},
        None,
    ),
    "dead-man cap: a short cap ends a long lease; a link back in time saves it": (
        [
            Step(0.0, "offer:a", ("offer:applied", "pub:a:first")),
            Step(0.5, "offer:b", ("offer:applied", "pub:b:first")),
            Step(1.0, "down"),
            Step(2.9, "tick"),
            Step(3.0, "up"),
            Step(3.5, "down"),
            Step(5.4, "tick"),
            Step(5.5, "tick", ("expired:a", "expired:b")),
        ],
        {"a": cmd("a", lease=60.0, period=30.0), "b": cmd("b", topic="/x", lease=60.0, period=30.0)},
        2.0,
    ),
}


@pytest.mark.parametrize("name", list(CASES))
def test_timeline(name: str) -> None:
    steps, commands, dead_man = CASES[name]
    run(steps, commands, dead_man)


def test_deadline_is_capped_by_receipt_plus_lease_when_the_clock_runs_behind() -> None:
    schedule = Schedule()
    a = cmd("a", lease=10.0, issued=100.0)  # issued "in the future" for this repeater's clock
    assert schedule.offer(a, T0).offer is Offer.APPLIED
    publish, changes = schedule.tick(T0 + 9.99)
    assert [c.status for c in changes] == []
    publish, changes = schedule.tick(T0 + 10.0)
    assert [c.status for c in changes] == ["expired"]
    assert publish == []


def test_restored_command_keeps_its_receipt_time_and_delivery() -> None:
    schedule = Schedule()
    a = cmd("a", lease=10.0)
    outcome = schedule.offer(a, T0 + 4.0, delivered=True, received_at=T0 + 0.5)
    assert outcome.offer is Offer.APPLIED
    assert schedule.published(a, T0 + 4.0, seen=True) == []  # delivered before the restart
    _, changes = schedule.tick(T0 + 10.0)
    assert [c.status for c in changes] == ["expired"]
    assert "after delivery" in changes[0].detail


def test_delivered_once_on_the_first_publish_a_subscriber_saw() -> None:
    schedule = Schedule()
    a = cmd("a")
    schedule.offer(a, T0)
    assert schedule.published(a, T0, seen=False) == []
    first = schedule.published(a, T0 + 1, seen=True)
    assert [(c.status, c.command.command_id) for c in first] == [("delivered", "a")]
    assert schedule.published(a, T0 + 2, seen=True) == []
    assert schedule.delivered(a)


def test_publish_report_for_a_superseded_command_is_ignored() -> None:
    schedule = Schedule()
    a, b = cmd("a"), cmd("b", issued=1.0)
    schedule.offer(a, T0)
    schedule.offer(b, T0 + 1)
    assert schedule.published(a, T0 + 1, seen=True) == []
    assert not schedule.delivered(a)


def test_remembered_command_is_a_duplicate_and_forgotten_after_its_lease() -> None:
    schedule = Schedule()
    a = cmd("a", lease=5.0)
    schedule.remember(a)
    assert schedule.offer(a, T0 + 1).offer is Offer.DUPLICATE
    schedule.tick(T0 + 5.0)
    assert ("a", "tb4_01") not in set(schedule.seen())
    assert schedule.offer(a, T0 + 5.0).offer is Offer.EXPIRED


def test_next_wakeup_follows_repeats_deadlines_and_the_dead_man() -> None:
    schedule = Schedule(dead_man=3.0)
    assert schedule.next_wakeup() is None
    schedule.offer(cmd("a", lease=10.0, period=4.0), T0)
    assert schedule.next_wakeup() == T0 + 4.0
    schedule.link_down(T0 + 0.5)
    assert schedule.next_wakeup() == T0 + 3.5
    schedule.link_up()
    assert schedule.next_wakeup() == T0 + 4.0


def test_dead_man_must_be_positive() -> None:
    with pytest.raises(ValueError, match="positive"):
        Schedule(dead_man=0)
