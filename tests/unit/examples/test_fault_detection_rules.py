"""The fault-detection rules as tables: event → failure, window → verdict, verdict → command."""

from __future__ import annotations

from typing import Any

import pytest

from fleetlink.examples.fault_detection.errors import BadRecordError, CorruptStateError
from fleetlink.examples.fault_detection.rules import (
    HAZARD_CLIFF,
    HAZARD_WHEEL_DROP,
    INITIAL_MEMORY,
    LightCommand,
    RobotMemory,
    RobotState,
    RuleConfig,
    Sensor,
    event_failure,
    step,
    window_complete,
    window_verdict,
)

RUNNING, FAILED = RobotState.RUNNING, RobotState.FAILED
BACKUP_LIMIT, BUMP, STALL, OBJECT_PROXIMITY = 0, 1, 3, 5
HEADER = {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "base_link"}


def ir(*values: Any) -> dict[str, Any]:
    return {"header": HEADER, "readings": [{"header": HEADER, "value": v} for v in values]}


def hazards(*types: Any) -> dict[str, Any]:
    return {"header": HEADER, "detections": [{"header": HEADER, "type": t} for t in types]}


def kidnap(value: Any) -> dict[str, Any]:
    return {"header": HEADER, "is_kidnapped": value}


DEFAULT = RuleConfig()


@pytest.mark.parametrize(
    ("sensor", "record", "config", "expected"),
    [
        # IR intensity: all readings strictly above the threshold (3000) and at least one
        (Sensor.IR_INTENSITY, ir(3500, 3200, 4000, 3001, 3900, 3100, 3300), DEFAULT, True),
        (Sensor.IR_INTENSITY, ir(3500, 3200, 4000, 12, 3900, 3100, 3300), DEFAULT, False),
        (Sensor.IR_INTENSITY, ir(3000, 3500), DEFAULT, False),  # equal is not above
        (Sensor.IR_INTENSITY, ir(3001), DEFAULT, True),
        (Sensor.IR_INTENSITY, ir(0, 0, 0, 0, 0, 0, 0), DEFAULT, False),
        (Sensor.IR_INTENSITY, ir(), DEFAULT, False),  # no readings: no evidence of failure
        (Sensor.IR_INTENSITY, ir(150, 160), RuleConfig(ir_threshold=100), True),
        (Sensor.IR_INTENSITY, ir(150, 60), RuleConfig(ir_threshold=100), False),
        (Sensor.IR_INTENSITY, ir(-5, -3), RuleConfig(ir_threshold=-10), True),
        # hazard detection: a wheel drop or a cliff among the detections
        (Sensor.HAZARD_DETECTION, hazards(HAZARD_WHEEL_DROP), DEFAULT, True),
        (Sensor.HAZARD_DETECTION, hazards(HAZARD_CLIFF), DEFAULT, True),
        (Sensor.HAZARD_DETECTION, hazards(BUMP, HAZARD_WHEEL_DROP), DEFAULT, True),
        (Sensor.HAZARD_DETECTION, hazards(BUMP), DEFAULT, False),
        (Sensor.HAZARD_DETECTION, hazards(BACKUP_LIMIT, STALL, OBJECT_PROXIMITY), DEFAULT, False),
        (Sensor.HAZARD_DETECTION, hazards(), DEFAULT, False),
        (Sensor.HAZARD_DETECTION, hazards(HAZARD_CLIFF), RuleConfig(failure_hazards=frozenset({4})), False),
        (Sensor.HAZARD_DETECTION, hazards(BUMP), RuleConfig(failure_hazards=frozenset({BUMP})), True),
        # kidnap status
        (Sensor.KIDNAP_STATUS, kidnap(True), DEFAULT, True),
        (Sensor.KIDNAP_STATUS, kidnap(False), DEFAULT, False),
    ],
)
def test_event_failure(sensor: Sensor, record: dict[str, Any], config: RuleConfig, expected: bool) -> None:
    assert event_failure(sensor, record, config) is expected


@pytest.mark.parametrize(
    ("sensor", "record", "reason"),
    [
        (Sensor.IR_INTENSITY, None, "record is not a mapping"),
        (Sensor.IR_INTENSITY, {"header": HEADER}, "missing field 'readings'"),
        (Sensor.IR_INTENSITY, {"readings": "3500"}, "readings is not a list"),
        (Sensor.IR_INTENSITY, {"readings": [{"header": HEADER}]}, "missing field 'value'"),
        (Sensor.IR_INTENSITY, ir("3500"), "readings[].value is not an integer"),
        (Sensor.IR_INTENSITY, ir(True), "readings[].value is not an integer"),
        (Sensor.IR_INTENSITY, {"readings": [7]}, "element is not a mapping"),
        (Sensor.HAZARD_DETECTION, {"header": HEADER}, "missing field 'detections'"),
        (Sensor.HAZARD_DETECTION, hazards(4.0), "detections[].type is not an integer"),
        (Sensor.HAZARD_DETECTION, {"detections": None}, "detections is not a list"),
        (Sensor.KIDNAP_STATUS, {"header": HEADER}, "missing field 'is_kidnapped'"),
        (Sensor.KIDNAP_STATUS, kidnap(1), "is_kidnapped is not a boolean"),
        (Sensor.KIDNAP_STATUS, [("is_kidnapped", True)], "not a mapping"),
    ],
)
def test_malformed_records_raise_with_context(sensor: Sensor, record: Any, reason: str) -> None:
    with pytest.raises(BadRecordError) as info:
        event_failure(sensor, record, DEFAULT)
    assert info.value.sensor == sensor
    assert reason in info.value.reason
    assert info.value.record is record
    assert str(sensor) in str(info.value)


@pytest.mark.parametrize(
    ("events", "failures", "min_events", "expected"),
    [
        (10, 10, 2, FAILED),  # every event says failure
        (10, 0, 2, RUNNING),  # every event says healthy
        (10, 9, 2, None),  # one healthy reading keeps the state
        (10, 1, 2, None),  # one spurious failure keeps the state
        (2, 2, 2, FAILED),
        (1, 1, 2, None),  # too few events to decide
        (1, 0, 2, None),
        (1, 1, 1, FAILED),
        (1, 0, 1, RUNNING),
        (0, 0, 1, None),  # an empty window never decides
        (0, 0, 0, None),
        (5, 5, 6, None),
        (6, 6, 6, FAILED),
    ],
)
def test_window_verdict(events: int, failures: int, min_events: int, expected: RobotState | None) -> None:
    assert window_verdict(events, failures, min_events) is expected


@pytest.mark.parametrize(("events", "failures"), [(3, 4), (3, -1)])
def test_window_verdict_rejects_impossible_counts(events: int, failures: int) -> None:
    with pytest.raises(ValueError, match="cannot hold"):
        window_verdict(events, failures, 1)


@pytest.mark.parametrize(
    ("memory", "verdict", "end", "new_memory", "command"),
    [
        # initial state: running, nothing judged; a healthy window changes nothing
        (INITIAL_MEMORY, RUNNING, 1000, RobotMemory(RUNNING, 1000), None),
        (INITIAL_MEMORY, None, 1000, RobotMemory(RUNNING, 1000), None),
        # running -> failed: one red command, stamped with the window end
        (INITIAL_MEMORY, FAILED, 2500, RobotMemory(FAILED, 2500), LightCommand("tb4_02", FAILED, 2500)),
        # failed stays failed on failed and mixed windows: no repeated command
        (RobotMemory(FAILED, 2500), FAILED, 2600, RobotMemory(FAILED, 2600), None),
        (RobotMemory(FAILED, 2500), None, 2700, RobotMemory(FAILED, 2700), None),
        # failed -> running: one green command
        (
            RobotMemory(FAILED, 2700),
            RUNNING,
            5000,
            RobotMemory(RUNNING, 5000),
            LightCommand("tb4_02", RUNNING, 5000),
        ),
        # a window ending before the newest one judged is stale: ignored entirely
        (RobotMemory(FAILED, 2700), RUNNING, 2699, RobotMemory(FAILED, 2700), None),
        (RobotMemory(RUNNING, 2700), FAILED, 100, RobotMemory(RUNNING, 2700), None),
        # a window re-judged at the same end (a late record inside it) still counts
        (
            RobotMemory(RUNNING, 2700),
            FAILED,
            2700,
            RobotMemory(FAILED, 2700),
            LightCommand("tb4_02", FAILED, 2700),
        ),
    ],
)
def test_step(
    memory: RobotMemory,
    verdict: RobotState | None,
    end: int,
    new_memory: RobotMemory,
    command: LightCommand | None,
) -> None:
    transition = step("tb4_02", memory, verdict, end)
    assert transition.memory == new_memory
    assert transition.command == command


@pytest.mark.parametrize(
    ("command", "rgb", "sec", "nanosec", "command_id"),
    [
        (
            LightCommand("tb4_02", FAILED, 1_700_000_002_345),
            (255, 0, 0),
            1_700_000_002,
            345_000_000,
            "tb4_02-failed-1700000002345",
        ),
        (LightCommand("tb4_02", RUNNING, 5000), (0, 255, 0), 5, 0, "tb4_02-running-5000"),
        (
            LightCommand("robot/with-dash", RUNNING, 999),
            (0, 255, 0),
            0,
            999_000_000,
            "robot/with-dash-running-999",
        ),
    ],
)
def test_light_command_record(
    command: LightCommand, rgb: tuple[int, int, int], sec: int, nanosec: int, command_id: str
) -> None:
    red, green, blue = rgb
    assert command.record() == {
        "header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": ""},
        "leds": [{"red": red, "green": green, "blue": blue}] * 6,
        "override_system": True,
    }
    assert command.command_id == command_id


@pytest.mark.parametrize("memory", [INITIAL_MEMORY, RobotMemory(FAILED, 0), RobotMemory(RUNNING, 2**62)])
def test_memory_round_trips_through_json(memory: RobotMemory) -> None:
    assert RobotMemory.from_json(memory.to_json()) == memory


@pytest.mark.parametrize(
    ("value", "reason"),
    [
        (None, "not a mapping"),
        ("failed", "not a mapping"),
        ({"state": "broken", "last_window_end_ms": 1}, "unknown state"),
        ({"last_window_end_ms": 1}, "unknown state"),
        ({"state": "failed"}, "no window end"),
        ({"state": "failed", "last_window_end_ms": "1"}, "no window end"),
        ({"state": "failed", "last_window_end_ms": True}, "no window end"),
    ],
)
def test_corrupt_memory_is_an_error(value: Any, reason: str) -> None:
    with pytest.raises(CorruptStateError) as info:
        RobotMemory.from_json(value)
    assert info.value.reason == reason
    assert info.value.value is value


@pytest.mark.parametrize(
    ("end_ms", "newest_ms", "complete"),
    [
        (10_000, 10_000, True),  # the window that ends at the newest event
        (10_000, 12_000, True),
        (12_000, 10_300, False),  # a window that starts at an event and ends in the future
        (10_000, None, False),
    ],
)
def test_only_windows_whose_end_an_event_reached_are_judged(
    end_ms: int, newest_ms: int | None, complete: bool
) -> None:
    assert window_complete(end_ms, newest_ms) is complete
