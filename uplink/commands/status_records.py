"""Command status records on Kafka: a small fixed Avro schema, keyed by robot.

``fleetlink.commands.status`` (``topics.command_status``), value registered under
``<topic>-value``, Confluent wire format::

    CommandStatus {command_id: string, robot: string, ros_topic: string,
                   status: string  (delivered | superseded | expired | rejected),
                   at: long (timestamp-millis), site: string, detail: string}

``site`` is empty when the uplink itself decided (e.g. a command that expired before it
could be forwarded).
"""

from __future__ import annotations

import copy
import io
from typing import Any

import fastavro

from fleetlink.schemas.single_object import confluent_frame
from fleetlink.wire.commands import StatusEvent

STATUS_SCHEMA: dict[str, Any] = {
    "type": "record",
    "name": "CommandStatus",
    "namespace": "fleetlink.commands",
    "doc": "What became of a command: delivered, superseded, expired or rejected.",
    "fields": [
        {"name": "command_id", "type": "string"},
        {"name": "robot", "type": "string"},
        {"name": "ros_topic", "type": "string"},
        {"name": "status", "type": "string", "doc": "delivered | superseded | expired | rejected"},
        {"name": "at", "type": {"type": "long", "logicalType": "timestamp-millis"}},
        {"name": "site", "type": "string", "default": ""},
        {"name": "detail", "type": "string", "default": ""},
    ],
}
_PARSED = fastavro.parse_schema(copy.deepcopy(STATUS_SCHEMA))


def status_datum(event: StatusEvent) -> dict[str, Any]:
    """The ``CommandStatus`` Avro datum of ``event`` (its detail cut to 2000 characters)."""
    return {
        "command_id": event.command_id,
        "robot": event.robot,
        "ros_topic": event.ros_topic,
        "status": event.status,
        "at": event.at_ms,
        "site": event.site,
        "detail": event.detail[:2000],
    }


def status_value(schema_id: int, event: StatusEvent) -> bytes:
    """The Kafka value of ``event``: Confluent header + Avro body."""
    out = io.BytesIO()
    datum = status_datum(event)
    # timestamp-millis takes an int here: write the raw long, not a datetime
    fastavro.schemaless_writer(out, _PARSED, datum)
    return confluent_frame(schema_id, out.getvalue())
