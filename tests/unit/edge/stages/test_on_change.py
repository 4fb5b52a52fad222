"""The on_change stage: deadband against the last forwarded value, heartbeat timing."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from fleetlink.edge.stages import FieldPathError, OnChangeStage
from fleetlink.edge.stages.on_change import changed
from tests.unit.edge.stages.messages import ODOMETRY_SCHEMA, sample, schema

MS = 1_000_000
NAN = math.nan
INF = math.inf


@pytest.mark.parametrize(
    ("old", "new", "deadband", "expected"),
    [
        (1.0, 1.04, 0.05, False),
        (1.0, 1.06, 0.05, True),
        (1.0, 0.94, 0.05, True),
        (1.0, 1.5, 0.5, False),  # strictly more than the deadband (values exact in binary)
        (1, 2, 0.0, True),
        (1, 1.0, 0.0, False),
        (NAN, NAN, 0.0, False),
        (NAN, 1.0, 0.5, True),
        (1.0, NAN, 0.5, True),
        (INF, INF, 0.0, False),
        (INF, -INF, 0.0, True),
        (1.0, INF, 1e300, True),
        (True, False, 5.0, True),  # bools are not numbers here
        (True, True, 0.0, False),
        ("dock", "dock", 1.0, False),
        ("dock", "undock", 1.0, True),
        (b"\x01", b"\x02", 10.0, True),
        ({"x": 1.0, "y": 2.0}, {"x": 1.01, "y": 2.0}, 0.05, False),
        ({"x": 1.0, "y": 2.0}, {"x": 1.01, "y": 2.1}, 0.05, True),
        ({"x": 1.0}, {"z": 1.0}, 0.05, True),
        ([1.0, 2.0], [1.01, 2.0], 0.05, False),
        ([1.0, 2.0], [1.0, 2.0, 3.0], 0.05, True),
        (["a"], ["b"], 0.05, True),
        (np.array([1.0, 2.0]), np.array([1.01, 2.04]), 0.05, False),
        (np.array([1.0, 2.0]), np.array([1.01, 2.06]), 0.05, True),
        (np.array([1.0, NAN]), np.array([1.0, NAN]), 0.0, False),
        (np.array([1.0, NAN]), np.array([1.0, 3.0]), 10.0, True),
        (np.array([1.0, INF]), np.array([1.0, INF]), 0.0, False),
        (np.array([1.0, INF]), np.array([1.0, -INF]), 0.0, True),
        (np.array([1, 2], dtype=np.int32), np.array([1, 2], dtype=np.int64), 0.0, False),
        (np.array([1.0, 2.0]), np.array([1.0]), 0.0, True),
        (np.array([1.0, 2.0]), [1.0, 2.0], 0.0, False),
        (np.array(["a", "b"]), np.array(["a", "c"]), 0.0, True),
        (None, None, 0.0, False),
    ],
)
def test_changed(old: Any, new: Any, deadband: float, expected: bool) -> None:
    assert changed(old, new, deadband) is expected


def run(stage: OnChangeStage, events: list[tuple[int, Any]], robot: str = "tb4_01") -> list[tuple[int, Any]]:
    """events: (now_ms, x value) to process, or (now_ms, "tick"). Returns (now_ms, x) forwarded."""
    out = []
    for now, what in events:
        if isinstance(what, str):
            emitted = stage.tick(now * MS)
        else:
            emitted = stage.process(sample({"x": what, "i": now}, robot=robot, topic=f"/{robot}/x"), now * MS)
        out += [(now, s.value["x"]) for s in emitted]
    return out


def assert_balanced(stage: OnChangeStage) -> None:
    c = stage.counters
    assert c.received == c.passed + c.dropped + c.errors + stage.held
    assert c.emitted == c.passed


@pytest.mark.parametrize(
    ("events", "forwarded"),
    [
        # first sample always; then only moves of more than 0.05 from the last FORWARDED value
        ([(0, 0.0), (100, 0.04), (200, 0.06), (300, 0.1), (400, 0.12)], [(0, 0.0), (200, 0.06), (400, 0.12)]),
        # a slow drift is caught once it adds up
        ([(0, 1.0), (1, 1.03), (2, 1.06), (3, 1.09), (4, 1.12)], [(0, 1.0), (2, 1.06), (4, 1.12)]),
        ([(0, 1.0), (1, 0.9), (2, 1.0)], [(0, 1.0), (1, 0.9), (2, 1.0)]),
        ([(0, 1.0), (1, NAN), (2, NAN), (3, 1.0)], [(0, 1.0), (1, NAN), (3, 1.0)]),
        ([(0, 1.0), (100, "tick"), (10_000, "tick")], [(0, 1.0)]),  # no heartbeat configured
    ],
)
def test_deadband(events: list[tuple[int, Any]], forwarded: list[tuple[int, Any]]) -> None:
    stage = OnChangeStage(["x"], deadband=0.05)
    got = run(stage, events)
    assert [t for t, _ in got] == [t for t, _ in forwarded]
    for (_, a), (_, b) in zip(got, forwarded, strict=True):
        assert a == b or (math.isnan(a) and math.isnan(b))
    assert_balanced(stage)


@pytest.mark.parametrize(
    ("events", "forwarded"),
    [
        # silence after a change: nothing to prove, nothing sent
        ([(0, 1.0), (999, "tick"), (1000, "tick"), (5000, "tick")], [(0, 1.0)]),
        # unchanged samples keep coming: one goes out per heartbeat, from process once due...
        (
            [(0, 1.0), (400, 1.0), (800, 1.0), (1000, 1.0), (1400, 1.0), (2000, 1.0)],
            [(0, 1.0), (1000, 1.0), (2000, 1.0)],
        ),
        # ...or from tick: the newest suppressed sample
        (
            [(0, 1.0), (300, 1.01), (600, 1.02), (999, "tick"), (1000, "tick"), (1500, "tick")],
            [(0, 1.0), (1000, 1.02)],
        ),
        # a real change resets the heartbeat clock
        (
            [(0, 1.0), (700, 2.0), (900, 2.0), (1000, "tick"), (1699, "tick"), (1700, "tick")],
            [(0, 1.0), (700, 2.0), (1700, 2.0)],
        ),
        # the heartbeat sample becomes the new reference for the deadband
        (
            [(0, 1.0), (500, 1.04), (1000, "tick"), (1100, 1.08), (1200, 1.1)],
            [(0, 1.0), (1000, 1.04), (1200, 1.1)],
        ),
    ],
)
def test_heartbeat(events: list[tuple[int, Any]], forwarded: list[tuple[int, Any]]) -> None:
    stage = OnChangeStage(["x"], deadband=0.05, heartbeat_ns=1000 * MS)
    assert run(stage, events) == forwarded
    assert_balanced(stage)


def test_keys_are_independent_and_any_field_counts() -> None:
    stage = OnChangeStage(["a", "b"], deadband=0.5)
    got = []
    for now, robot, a, b in [
        (0, "r1", 0, 0),
        (1, "r2", 0, 0),
        (2, "r1", 0, 1),
        (3, "r2", 0.2, 0.2),
        (4, "r1", 0, 1),
    ]:
        got += [(now, s.robot) for s in stage.process(sample({"a": a, "b": b}, robot=robot), now)]
    assert got == [(0, "r1"), (1, "r2"), (2, "r1")]


def test_missing_field_is_an_error_not_a_change() -> None:
    stage = OnChangeStage(["pose.x"])
    assert stage.process(sample({"pose": {"x": 1}}), 0)
    assert stage.process(sample({"pose": {}}), 1) == []
    assert stage.process(sample({"pose": 3}), 2) == []
    assert stage.counters.errors == 2
    assert stage.last_error is not None
    assert_balanced(stage)


def test_output_schema_checks_paths() -> None:
    odom = schema(ODOMETRY_SCHEMA)
    assert OnChangeStage(["pose.pose.position.x", "twist.twist"]).output_schema(odom) is odom
    with pytest.raises(FieldPathError, match=r"'pose\.position\.x'"):
        OnChangeStage(["pose.position.x"]).output_schema(odom)


@pytest.mark.parametrize(("fields", "deadband"), [([], 0.0), (["x"], -1.0), (["x"], NAN)])
def test_rejects_bad_options(fields: list[str], deadband: float) -> None:
    with pytest.raises(ValueError, match="on_change"):
        OnChangeStage(fields, deadband)


def test_values_that_cannot_be_compared_are_errors() -> None:
    stage = OnChangeStage(["x"])
    assert stage.process(sample({"x": np.array([1.0, 2.0])}), 0)
    assert stage.process(sample({"x": [[1.0], [1.0, 2.0]]}), 1) == []  # ragged: numpy refuses it
    assert stage.counters.errors == 1
    assert_balanced(stage)
