"""Registration events: the Avro record on the registrations topic and the ROS JSON."""

from __future__ import annotations

import io
import json

import fastavro
import pytest

from fleetlink.edge.runtime.registration import (
    EVENT_FINGERPRINT,
    EVENT_SCHEMA_JSON,
    RobotChange,
    event_json,
    event_record,
)
from fleetlink.roswire.robots import Reason, RobotEvent, RobotEventKind
from fleetlink.schemas.single_object import fingerprint
from fleetlink.wire import split_single_object
from fleetlink.wire.robot_events import EVENT_SCHEMA


@pytest.mark.parametrize(
    ("kind", "reason", "registered"),
    [
        (RobotEventKind.REGISTERED, Reason.DISCOVERED, True),
        (RobotEventKind.REGISTERED, Reason.EXPLICIT, True),
        (RobotEventKind.DEREGISTERED, Reason.LIVELINESS_LOST, False),
    ],
)
def test_event_record(kind: RobotEventKind, reason: Reason, registered: bool) -> None:
    change = RobotChange.from_event(RobotEvent(kind, "tb4_07", "turtlebot4", reason, 12.5), 1_700_000_000_123)
    assert change.registered is registered
    record = event_record(change, site="wh-a", edge_id="e1", topic="fleetlink.robots")
    assert (record.kafka_topic, record.key, record.timestamp_ms) == (
        "fleetlink.robots",
        b"tb4_07",
        1_700_000_000_123,
    )
    assert dict(record.headers) == {
        "fleetlink.site": b"wh-a",
        "fleetlink.robot": b"tb4_07",
        "fleetlink.edge": b"e1",
    }
    fp, body = split_single_object(record.value)
    assert fp == EVENT_FINGERPRINT == fingerprint(EVENT_SCHEMA) == fingerprint(EVENT_SCHEMA_JSON)
    datum = fastavro.schemaless_reader(io.BytesIO(bytes(body)), fastavro.parse_schema(EVENT_SCHEMA), None)
    assert isinstance(datum, dict)
    assert datum["timestamp"].timestamp() == pytest.approx(1_700_000_000.123)
    datum.pop("timestamp")
    assert datum == {
        "robot": "tb4_07",
        "robot_type": "turtlebot4",
        "site": "wh-a",
        "edge_id": "e1",
        "event": "registered" if registered else "deregistered",
        "reason": reason.value,
    }
    assert json.loads(event_json(change, site="wh-a", edge_id="e1")) == {
        "robot": "tb4_07",
        "robot_type": "turtlebot4",
        "site": "wh-a",
        "edge_id": "e1",
        "event": "registered" if registered else "deregistered",
        "reason": reason.value,
        "timestamp": 1_700_000_000_123,
    }
