"""The Kafka records of service calls and action goals: Avro schemas and values (pure).

Each mapping's topics get a record schema that wraps the ROS type's own Avro schema
(``fleetlink.schemas.avro_schema``), so the response, feedback and result fields are exactly
what the type's CDR converts to:

* ``reply_to`` (key = robot): ``{correlation_id, robot, service, status, detail, requested_at,
  at, site, response: null | <Name>_Response}``;
* ``feedback_to`` (key = goal id): ``{goal_id, robot, action, at, feedback: <Name>_Feedback}``;
* ``result_to`` (key = goal id): ``{goal_id, robot, action, status, detail, requested_at, at,
  site, result: null | <Name>_Result}`` — ``accepted`` first, then one final status;
  cancel outcomes (``cancel-…``) go here too.

The wrapped value is written last, so a value is the envelope's fields (fastavro) followed by
the union branch and the converted body as it is.
"""

from __future__ import annotations

import copy
import io
from typing import Any

import fastavro

CANCEL_SCHEMA: dict[str, Any] = {
    "type": "record",
    "name": "CancelGoal",
    "namespace": "fleetlink.actions",
    "doc": "Cancel an action goal: the record's key is the goal id too.",
    "fields": [
        {"name": "goal_id", "type": "string", "doc": "the goal id (UUID text) of the goal record"},
        {"name": "robot", "type": "string"},
    ],
}
"""What a producer writes to an action mapping's ``cancel_from`` topic (any schema with a
``robot`` string field, and ``goal_id`` unless the key holds it, will do)."""

_MILLIS = {"type": "long", "logicalType": "timestamp-millis"}


def _head(kind: str) -> list[dict[str, Any]]:
    if kind == "reply":
        first = [
            {"name": "correlation_id", "type": "string"},
            {"name": "robot", "type": "string"},
            {"name": "service", "type": "string", "doc": "the ROS service called"},
        ]
    else:
        first = [
            {"name": "goal_id", "type": "string"},
            {"name": "robot", "type": "string"},
            {"name": "action", "type": "string", "doc": "the ROS action"},
        ]
    if kind == "feedback":
        return [*first, {"name": "at", "type": _MILLIS}]
    return [
        *first,
        {"name": "status", "type": "string"},
        {"name": "detail", "type": "string", "default": ""},
        {"name": "requested_at", "type": _MILLIS, "doc": "the request's Kafka record timestamp"},
        {"name": "at", "type": _MILLIS},
        {"name": "site", "type": "string", "default": ""},
    ]


_TAIL = {"reply": "response", "feedback": "feedback", "result": "result"}
_DOC = {
    "reply": "A ROS service call's outcome: ok (with the response), timeout, unavailable, error, "
    "expired or rejected.",
    "feedback": "Feedback of a running ROS action goal.",
    "result": "A ROS action goal's status: accepted, then succeeded, canceled or aborted (with the "
    "result), rejected, timeout, unavailable, error or expired; cancel-… for cancel requests.",
}


def record_schema(kind: str, ros_schema: dict[str, Any], name: str, namespace: str) -> dict[str, Any]:
    """The value schema of a mapping's ``kind`` topic (``reply``, ``feedback`` or ``result``)."""
    wrapped: Any = copy.deepcopy(ros_schema)
    tail: dict[str, Any] = {"name": _TAIL[kind], "type": wrapped}
    if kind != "feedback":
        tail = {"name": _TAIL[kind], "type": ["null", wrapped], "default": None}
    return {
        "type": "record",
        "name": name,
        "namespace": namespace,
        "doc": _DOC[kind],
        "fields": [*_head(kind), tail],
    }


class RecordWriter:
    """Writes values of one :func:`record_schema`: the head with fastavro, the body as it is."""

    def __init__(self, kind: str, schema: dict[str, Any]) -> None:
        self.kind = kind
        self.schema = schema
        head = {"type": "record", "name": "Head", "fields": _head(kind)}
        self._head = fastavro.parse_schema(head)

    def value(self, head: dict[str, Any], avro_body: bytes | None) -> bytes:
        """``head``'s fields, then the wrapped value (``None``: the union's null branch)."""
        out = io.BytesIO()
        fastavro.schemaless_writer(out, self._head, head)
        if self.kind == "feedback":
            if avro_body is None:
                raise ValueError("feedback needs its body")
            return out.getvalue() + avro_body
        if avro_body is None:
            return out.getvalue() + b"\x00"  # union branch 0: null
        return out.getvalue() + b"\x02" + avro_body  # union branch 1 (zig-zag varint)
