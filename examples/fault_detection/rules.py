"""The fault-detection rules, as pure functions: no Kafka, no clock, no disk.

Three steps, each a function the app calls from a stream operation:

1. **Event → failure** (``event_failure``): one sensor record says "failure" or "healthy".

   ===================  ====================================================================
   sensor               failure when
   ===================  ====================================================================
   kidnap_status        ``is_kidnapped`` is true
   hazard_detection     any detection's ``type`` is in the failure hazards (default
                        ``WHEEL_DROP`` = 4 and ``CLIFF`` = 2: the wheels hang in the air)
   ir_intensity         there is at least one reading and *every* reading's ``value`` is
                        strictly above the threshold (default 3000): something covers all
                        the sensors at once, as when the robot is held in someone's hands
   ===================  ====================================================================

2. **Window → verdict** (``window_verdict``): over the events of one robot in a sliding
   window, ``FAILED`` when every event says failure, ``RUNNING`` when every event says
   healthy, ``None`` (no opinion: keep the current state) when they are mixed or when the
   window holds fewer than ``min_events`` events.

3. **Verdict → transition** (``step``): the per-robot memory (state + end of the newest
   window judged) moves to the verdict; a change of state yields exactly one
   ``LightCommand`` (red on failure, green on recovery). Windows that end before the newest
   one already judged (a late record re-opening an old window) are ignored, so the state
   only ever moves forward in event time.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from fleetlink.examples.fault_detection.errors import BadRecordError, CorruptStateError

__all__ = [
    "HAZARD_CLIFF",
    "HAZARD_WHEEL_DROP",
    "INITIAL_MEMORY",
    "LED_COUNT",
    "LightCommand",
    "RobotMemory",
    "RobotState",
    "RuleConfig",
    "Sensor",
    "Transition",
    "event_failure",
    "hazard_failure",
    "ir_failure",
    "kidnap_failure",
    "step",
    "window_complete",
    "window_verdict",
]

# irobot_create_msgs/msg/HazardDetection constants
HAZARD_CLIFF = 2
HAZARD_WHEEL_DROP = 4
# irobot_create_msgs/msg/LightringLeds: LedColor[6] leds
LED_COUNT = 6


class Sensor(enum.StrEnum):
    """Where an event came from; one input topic each."""

    IR_INTENSITY = "ir_intensity"
    HAZARD_DETECTION = "hazard_detection"
    KIDNAP_STATUS = "kidnap_status"


class RobotState(enum.StrEnum):
    """A robot's state as the rules judge it: running, or failed (red light ring)."""

    RUNNING = "running"
    FAILED = "failed"


@dataclass(frozen=True)
class RuleConfig:
    """The tunable parts of the rules."""

    ir_threshold: int = 3000
    failure_hazards: frozenset[int] = field(default=frozenset({HAZARD_WHEEL_DROP, HAZARD_CLIFF}))
    min_events: int = 2


# --- 1. event -> failure ----------------------------------------------------------------


def _field(obj: Any, name: str, sensor: Sensor, record: Any) -> Any:
    """``obj[name]`` of a (possibly nested) part of ``record``; errors carry the whole record."""
    if not isinstance(obj, Mapping):
        raise BadRecordError(sensor, f"{'record' if obj is record else 'element'} is not a mapping", record)
    if name not in obj:
        raise BadRecordError(sensor, f"missing field {name!r}", record)
    return obj[name]


def _int(value: Any, what: str, sensor: Sensor, record: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise BadRecordError(sensor, f"{what} is not an integer", record)
    return value


def _list(value: Any, what: str, sensor: Sensor, record: Any) -> list[Any]:
    if not isinstance(value, list):
        raise BadRecordError(sensor, f"{what} is not a list", record)
    return value


def ir_failure(record: Any, threshold: int) -> bool:
    """IrIntensityVector: every reading strictly above ``threshold`` (and at least one)."""
    sensor = Sensor.IR_INTENSITY
    readings = _list(_field(record, "readings", sensor, record), "readings", sensor, record)
    values = [_int(_field(r, "value", sensor, record), "readings[].value", sensor, record) for r in readings]
    return bool(values) and all(v > threshold for v in values)


def hazard_failure(record: Any, failure_hazards: frozenset[int]) -> bool:
    """HazardDetectionVector: any detection whose type is one of ``failure_hazards``."""
    sensor = Sensor.HAZARD_DETECTION
    detections = _list(_field(record, "detections", sensor, record), "detections", sensor, record)
    types = [_int(_field(d, "type", sensor, record), "detections[].type", sensor, record) for d in detections]
    return any(t in failure_hazards for t in types)


def kidnap_failure(record: Any) -> bool:
    """KidnapStatus: ``is_kidnapped``."""
    sensor = Sensor.KIDNAP_STATUS
    value = _field(record, "is_kidnapped", sensor, record)
    if not isinstance(value, bool):
        raise BadRecordError(sensor, "is_kidnapped is not a boolean", record)
    return value


def event_failure(sensor: Sensor, record: Any, config: RuleConfig) -> bool:
    """Does this one record say the robot has failed? Raises BadRecordError on a malformed record."""
    if sensor is Sensor.IR_INTENSITY:
        return ir_failure(record, config.ir_threshold)
    if sensor is Sensor.HAZARD_DETECTION:
        return hazard_failure(record, config.failure_hazards)
    return kidnap_failure(record)


# --- 2. window -> verdict ---------------------------------------------------------------


def window_complete(end_ms: int, newest_event_ms: int | None) -> bool:
    """Whether a sliding window covers its whole duration of events.

    A sliding window is emitted as it changes, including the windows that *start* at an event
    and end in the future: those hold only the newest events (a fault 0.3 s old would fill one
    with failures alone). Only a window whose end has been reached by an event is judged, so
    "every event in the window" always means a full window's worth.
    """
    return newest_event_ms is not None and newest_event_ms >= end_ms


def window_verdict(events: int, failures: int, min_events: int) -> RobotState | None:
    """All events failed → FAILED; none failed → RUNNING; mixed or too few events → None."""
    if failures < 0 or failures > events:
        raise ValueError(f"window with {events} events cannot hold {failures} failures")
    if events < max(min_events, 1):
        return None
    if failures == events:
        return RobotState.FAILED
    if failures == 0:
        return RobotState.RUNNING
    return None


# --- 3. verdict -> transition -> command ------------------------------------------------


@dataclass(frozen=True)
class RobotMemory:
    """What the state store keeps per robot: its state and the end of the newest window judged."""

    state: RobotState
    last_window_end_ms: int

    def to_json(self) -> dict[str, Any]:
        """The memory as JSON-ready data for the state store."""
        return {"state": self.state.value, "last_window_end_ms": self.last_window_end_ms}

    @classmethod
    def from_json(cls, data: Any) -> RobotMemory:
        """Read back what ``to_json`` stored; anything else is an error (a broken store)."""
        if not isinstance(data, Mapping):
            raise CorruptStateError("not a mapping", data)
        state, end = data.get("state"), data.get("last_window_end_ms")
        if state not in {s.value for s in RobotState}:
            raise CorruptStateError("unknown state", data)
        if isinstance(end, bool) or not isinstance(end, int):
            raise CorruptStateError("no window end", data)
        return cls(RobotState(state), end)


# Every robot starts running, before any window has been judged: no command at start-up.
INITIAL_MEMORY = RobotMemory(RobotState.RUNNING, -1)

_COLOURS: dict[RobotState, tuple[int, int, int]] = {
    RobotState.FAILED: (255, 0, 0),
    RobotState.RUNNING: (0, 255, 0),
}


@dataclass(frozen=True)
class LightCommand:
    """One light-ring command: the robot, the state it entered, and when (window end, ms)."""

    robot: str
    state: RobotState
    stamp_ms: int

    @property
    def colour(self) -> tuple[int, int, int]:
        """The light ring's (red, green, blue): red for failed, green for running."""
        return _COLOURS[self.state]

    @property
    def command_id(self) -> str:
        """Deterministic: re-processing the same decision yields the same id (receivers can dedupe)."""
        return f"{self.robot}-{self.state.value}-{self.stamp_ms}"

    def record(self) -> dict[str, Any]:
        """The ``irobot_create_msgs/msg/LightringLeds`` record (Avro field names = ROS names)."""
        red, green, blue = self.colour
        sec, msec = divmod(self.stamp_ms, 1000)
        return {
            "header": {"stamp": {"sec": sec, "nanosec": msec * 1_000_000}, "frame_id": ""},
            "leds": [{"red": red, "green": green, "blue": blue} for _ in range(LED_COUNT)],
            "override_system": True,
        }


@dataclass(frozen=True)
class Transition:
    """The outcome of one window's verdict: the robot's new memory and the command, if its state changed."""

    memory: RobotMemory
    command: LightCommand | None


def step(robot: str, memory: RobotMemory, verdict: RobotState | None, window_end_ms: int) -> Transition:
    """Apply one window's verdict to a robot's memory; a command only on a change of state."""
    if window_end_ms < memory.last_window_end_ms:
        return Transition(memory, None)
    if verdict is None or verdict is memory.state:
        return Transition(RobotMemory(memory.state, window_end_ms), None)
    return Transition(RobotMemory(verdict, window_end_ms), LightCommand(robot, verdict, window_end_ms))
