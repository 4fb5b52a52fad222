"""The throttle stage on a processing-time timeline, both modes."""

from __future__ import annotations

import pytest

from fleetlink.edge.stages import Sample, ThrottleStage
from tests.unit.edge.stages.messages import sample

MS = 1_000_000
# a timeline: (now in ms, "name" to process a sample, "tick" to tick, optional robot)
Event = tuple[int, str] | tuple[int, str, str]


def run(stage: ThrottleStage, events: list[Event]) -> list[tuple[int, list[str]]]:
    """Returns (now_ms, names emitted) for every event that emitted something."""
    out = []
    for event in events:
        now, what = event[0], event[1]
        robot = event[2] if len(event) == 3 else "tb4_01"
        if what == "tick":
            emitted = stage.tick(now * MS)
        else:
            emitted = stage.process(sample({"name": what}, robot=robot, topic=f"/{robot}/x"), now * MS)
        if emitted:
            out.append((now, [str(s.value["name"]) for s in emitted]))
    return out


def assert_balanced(stage: ThrottleStage) -> None:
    c = stage.counters
    assert c.received == c.passed + c.dropped + stage.held
    assert c.emitted == c.passed


@pytest.mark.parametrize(
    ("events", "expected", "dropped"),
    [
        # 10 Hz: periods [0,100), [100,200), ... ms; the first of each period goes out at once
        (
            [(0, "a"), (50, "b"), (99, "c"), (100, "d"), (150, "e"), (250, "f"), (260, "g")],
            [(0, ["a"]), (100, ["d"]), (250, ["f"])],
            4,
        ),
        # periods are aligned on the clock, not on the first sample
        ([(95, "a"), (101, "b"), (180, "c"), (201, "d")], [(95, ["a"]), (101, ["b"]), (201, ["d"])], 1),
        # robots are throttled independently
        ([(0, "a1", "r1"), (1, "a2", "r2"), (2, "b1", "r1"), (3, "b2", "r2")], [(0, ["a1"]), (1, ["a2"])], 2),
        # ticks never emit in this mode
        ([(0, "a"), (150, "tick"), (500, "tick")], [(0, ["a"])], 0),
    ],
)
def test_keep_first(events: list[Event], expected: list[tuple[int, list[str]]], dropped: int) -> None:
    stage = ThrottleStage(10, "first")
    assert run(stage, events) == expected
    assert stage.counters.dropped == dropped
    assert_balanced(stage)


@pytest.mark.parametrize(
    ("events", "expected", "dropped"),
    [
        # the newest sample of a period goes out once the period is over, from process...
        ([(0, "a"), (50, "b"), (99, "c"), (100, "d"), (150, "e")], [(100, ["c"])], 3),
        # ...or from tick, not before the boundary
        ([(0, "a"), (50, "b"), (99, "tick"), (100, "tick"), (101, "tick")], [(100, ["b"])], 1),
        (
            [
                (10, "a"),
                (99, "tick"),
                (199, "tick"),
                (200, "tick"),
                (250, "b"),
                (299, "tick"),
                (300, "tick"),
                (900, "tick"),
            ],
            [(199, ["a"]), (300, ["b"])],
            0,
        ),
        # a held sample is emitted before the next one is held (order kept)
        ([(0, "a"), (120, "b"), (240, "c"), (360, "tick")], [(120, ["a"]), (240, ["b"]), (360, ["c"])], 0),
        # robots are independent; one tick emits for every robot that is due
        ([(0, "a1", "r1"), (10, "a2", "r2"), (20, "b1", "r1"), (100, "tick")], [(100, ["b1", "a2"])], 1),
    ],
)
def test_keep_latest(events: list[Event], expected: list[tuple[int, list[str]]], dropped: int) -> None:
    stage = ThrottleStage(10, "latest")
    assert run(stage, events) == expected
    assert stage.counters.dropped == dropped
    assert_balanced(stage)


@pytest.mark.parametrize("keep", ["first", "latest"])
def test_rate_is_bounded_over_a_long_run(keep: str) -> None:
    stage = ThrottleStage(7.5, keep)  # type: ignore[arg-type]
    out: list[Sample] = []
    for i in range(10_000):  # 1 kHz for 10 s
        out += stage.process(sample({"i": i}), i * MS)
    out += stage.tick(10_000 * MS)
    period = round(1e9 / 7.5)
    assert len(out) == 9_999 * MS // period + 1 == 75  # one per period touched
    assert_balanced(stage)


def test_rejects_non_positive_rate() -> None:
    with pytest.raises(ValueError, match="hz must be > 0"):
        ThrottleStage(0)


def test_time_going_backwards_does_not_open_a_new_period() -> None:
    stage = ThrottleStage(10, "first")
    assert run(stage, [(500, "a"), (420, "b"), (530, "c")]) == [(500, ["a"])]
