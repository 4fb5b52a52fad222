"""The command wire contract between the uplink and the repeaters (pure: bytes in, bytes out).

Three messages travel on a site's keys (``fleetlink/<site>/…``):

* **command envelope** — the uplink's query on ``fleetlink/<site>/command/<robot>/<command>``::

      "FLC" | version (1) | flags (bit 0: zlib) | rest
      rest = u32 header length (big-endian) | header (JSON, UTF-8) | value

  ``value`` is the command's Avro record in single-object encoding (``C3 01`` + 8-byte schema
  fingerprint + body); the header carries ids, targets and times, and the writer schema's
  JSON text unless the uplink knows the site already has it (then a repeater that does not
  answers ``need-schema`` and the uplink sends it again with the schema).
* **reply** — the repeater's answer to that query (JSON): what it did with the command.
* **status batch** — the repeater's query on ``fleetlink/<site>/command-status/<repeater>``
  (JSON): delivered / superseded / expired / rejected events; an empty batch is a heartbeat.
  The uplink answers with a :class:`StatusAck` once Kafka has the records.

Every decoder checks every field and raises :class:`~fleetlink.wire.errors.EnvelopeError` naming it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, Literal, get_args

from fleetlink.common.names import ros_topic_problem, ros_type_problem
from fleetlink.wire.envelope import (
    COMPRESS_ABOVE,
    Fields,
    json_object,
    pack_envelope,
    pack_json,
    unpack_envelope,
    unpack_json,
)
from fleetlink.wire.errors import EnvelopeError, WireError
from fleetlink.wire.keys import check_key_chunk, check_key_name
from fleetlink.wire.records import single_object, split_single_object

MAGIC = b"FLC"

Result = Literal["applied", "duplicate", "expired", "superseded", "rejected", "need-schema"]
RESULTS: frozenset[str] = frozenset(get_args(Result))
Status = Literal["delivered", "superseded", "expired", "rejected"]
STATUSES: frozenset[str] = frozenset(get_args(Status))
SETTLED: frozenset[str] = frozenset({"applied", "duplicate", "expired", "superseded", "rejected"})
"""Results after which the uplink may commit: the site has taken responsibility or refused for good."""


@dataclass(frozen=True, slots=True)
class CommandEnvelope:
    """A command for a repeater: publish ``body`` on a robot's ROS topic every ``period_ms`` while its
    lease holds."""

    command_id: str
    robot: str
    ros_topic: str
    ros_type: str
    mapping: str
    issued_at_ms: int
    """Start of the lease: the Kafka record's timestamp (ms since the epoch)."""
    lease_until_ms: int
    period_ms: int
    schema_fp: bytes
    body: bytes
    """The Avro body, written with the schema whose fingerprint is ``schema_fp``."""
    schema: str | None = None
    """The writer schema's JSON text, or None when the uplink expects the repeater to know it."""
    qos: str | None = None
    """rmw_zenoh's compact QoS string for the repeater's publisher (None: reliable, volatile, depth 10)."""
    order: int = 0
    """Tie-break between commands with the same timestamp (the Kafka offset)."""
    source: str = ""
    """Where the command came from: ``<topic>:<partition>:<offset>``."""

    @property
    def lease_ms(self) -> int:
        """How long the command is valid from when it was issued, in milliseconds."""
        return self.lease_until_ms - self.issued_at_ms

    def without_schema(self) -> CommandEnvelope:
        """A copy without the writer schema's text, for a site that already has it."""
        return _replace_schema(self, None)

    def with_schema(self, schema: str) -> CommandEnvelope:
        """A copy carrying ``schema``, the writer schema's JSON text."""
        return _replace_schema(self, schema)


def _replace_schema(env: CommandEnvelope, schema: str | None) -> CommandEnvelope:
    return CommandEnvelope(
        env.command_id,
        env.robot,
        env.ros_topic,
        env.ros_type,
        env.mapping,
        env.issued_at_ms,
        env.lease_until_ms,
        env.period_ms,
        env.schema_fp,
        env.body,
        schema,
        env.qos,
        env.order,
        env.source,
    )


@dataclass(frozen=True, slots=True)
class CommandReply:
    """A repeater's answer to a command envelope: what it did with the command (``result``) and why."""

    command_id: str
    robot: str
    result: Result
    detail: str = ""
    site: str = ""
    repeater: str = ""


@dataclass(frozen=True, slots=True)
class StatusEvent:
    """What later became of a command at a site: delivered, superseded, expired or rejected (``at_ms``:
    when)."""

    command_id: str
    robot: str
    ros_topic: str
    status: Status
    at_ms: int
    site: str = ""
    detail: str = ""


@dataclass(frozen=True, slots=True)
class StatusBatch:
    """The status events one repeater of ``site`` sends in one query; an empty batch is a heartbeat."""

    repeater: str
    site: str
    events: tuple[StatusEvent, ...] = field(default_factory=tuple)


@dataclass(frozen=True, slots=True)
class StatusAck:
    """The uplink's answer to a status or outcome batch: how many records Kafka took (0 and ``detail`` when
    it failed)."""

    accepted: int
    detail: str = ""


# -- command envelope -----------------------------------------------------------------------


def encode_envelope(env: CommandEnvelope, *, compress_above: int = COMPRESS_ABOVE) -> bytes:
    """Check ``env`` and pack it as an ``FLC`` envelope, zlib-compressed when larger than
    ``compress_above`` bytes and smaller so."""
    check_envelope(env)
    header: dict[str, Any] = {
        "id": env.command_id,
        "robot": env.robot,
        "topic": env.ros_topic,
        "type": env.ros_type,
        "mapping": env.mapping,
        "issued": env.issued_at_ms,
        "until": env.lease_until_ms,
        "period": env.period_ms,
        "order": env.order,
    }
    if env.source != env.command_id:
        header["source"] = env.source
    if env.schema is not None:
        header["schema"] = env.schema
    if env.qos is not None:
        header["qos"] = env.qos
    tail = single_object(env.schema_fp, env.body)
    return pack_envelope(MAGIC, header, tail, compress_above=compress_above)


def decode_envelope(data: bytes) -> CommandEnvelope:
    """Parse and check a command envelope; raises :class:`EnvelopeError` naming the field that is wrong."""
    header, value = unpack_envelope(data, MAGIC, "command envelope")
    try:
        fp, view = split_single_object(value)
        body = bytes(view)
    except WireError as exc:
        raise EnvelopeError("command envelope", f"value: {exc}", data) from None
    get = Fields(header, "command envelope", data)
    env = CommandEnvelope(
        command_id=get.text("id"),
        robot=get.text("robot"),
        ros_topic=get.text("topic"),
        ros_type=get.text("type"),
        mapping=get.text("mapping"),
        issued_at_ms=get.integer("issued"),
        lease_until_ms=get.integer("until"),
        period_ms=get.integer("period"),
        schema_fp=fp,
        body=body,
        schema=get.optional_text("schema"),
        qos=get.optional_text("qos"),
        order=get.integer("order"),
        source=get.text("source", allow_empty=True) if "source" in header else get.text("id"),
    )
    try:
        check_envelope(env)
    except EnvelopeError as exc:
        raise EnvelopeError("command envelope", exc.reason, data) from None
    return env


def check_envelope(env: CommandEnvelope) -> None:
    """Raise :class:`EnvelopeError` unless every field of ``env`` is usable."""

    def bad(reason: str) -> EnvelopeError:
        return EnvelopeError("command envelope", reason)

    if not env.command_id or len(env.command_id) > 1000:
        raise bad("command id must have 1 to 1000 characters")
    try:
        check_key_name(env.robot, "robot")
        check_key_chunk(env.mapping, "command")
    except WireError as exc:
        raise bad(str(exc)) from None
    problem = ros_topic_problem(env.ros_topic)
    if problem is not None:
        raise bad(f"ROS topic {env.ros_topic!r}: {problem}")
    problem = ros_type_problem(env.ros_type)
    if problem is not None:
        raise bad(f"ROS type {env.ros_type!r} {problem}")
    if env.issued_at_ms < 0 or env.lease_until_ms < env.issued_at_ms:
        raise bad(f"lease [{env.issued_at_ms}, {env.lease_until_ms}] ms is not a time span")
    if env.period_ms <= 0:
        raise bad(f"period {env.period_ms} ms must be positive")
    if len(env.schema_fp) != 8:
        raise bad(f"schema fingerprint has {len(env.schema_fp)} bytes, not 8")
    if env.order < 0:
        raise bad(f"order {env.order} must not be negative")


# -- reply ----------------------------------------------------------------------------------


def encode_reply(reply: CommandReply) -> bytes:
    """Compact JSON of ``reply``, empty fields left out; raises :class:`EnvelopeError` for an unknown
    result."""
    if reply.result not in RESULTS:
        raise EnvelopeError("command reply", f"result {reply.result!r} is not one of {sorted(RESULTS)}")
    obj = {
        "id": reply.command_id,
        "robot": reply.robot,
        "result": reply.result,
        "detail": reply.detail,
        "site": reply.site,
        "repeater": reply.repeater,
    }
    return json.dumps({k: v for k, v in obj.items() if v}, separators=(",", ":")).encode()


def decode_reply(data: bytes) -> CommandReply:
    """Parse and check a repeater's reply; raises :class:`EnvelopeError` naming the field that is wrong."""
    get = Fields(json_object(data, "command reply", data), "command reply", data)
    result = get.text("result")
    if result not in RESULTS:
        raise EnvelopeError("command reply", f"result {result!r} is not one of {sorted(RESULTS)}", data)
    return CommandReply(
        get.text("id"),
        get.text("robot"),
        result,  # type: ignore[arg-type]
        get.text("detail", allow_empty=True),
        get.text("site", allow_empty=True),
        get.text("repeater", allow_empty=True),
    )


# -- status ---------------------------------------------------------------------------------


def encode_status_batch(batch: StatusBatch, *, compress_above: int = COMPRESS_ABOVE) -> bytes:
    """JSON, zlib-compressed when larger than ``compress_above`` bytes (JSON starts with ``{``)."""
    for event in batch.events:
        if event.status not in STATUSES:
            raise EnvelopeError("status batch", f"status {event.status!r} is not one of {sorted(STATUSES)}")
    return pack_json(
        {
            "repeater": batch.repeater,
            "site": batch.site,
            "events": [status_to_json(e) for e in batch.events],
        },
        compress_above=compress_above,
    )


def status_to_json(event: StatusEvent) -> dict[str, Any]:
    """The JSON object of one status event."""
    return {
        "id": event.command_id,
        "robot": event.robot,
        "topic": event.ros_topic,
        "status": event.status,
        "at": event.at_ms,
        "site": event.site,
        "detail": event.detail,
    }


def status_from_json(obj: object, data: bytes = b"") -> StatusEvent:
    """Read and check one status event's JSON object; ``data`` is the whole message, quoted in errors
    (:class:`EnvelopeError`)."""
    if not isinstance(obj, dict):
        raise EnvelopeError("status event", "not a JSON object", data)
    get = Fields(obj, "status event", data)
    status = get.text("status")
    if status not in STATUSES:
        raise EnvelopeError("status event", f"status {status!r} is not one of {sorted(STATUSES)}", data)
    return StatusEvent(
        get.text("id"),
        get.text("robot"),
        get.text("topic"),
        status,  # type: ignore[arg-type]
        get.integer("at"),
        get.text("site", allow_empty=True),
        get.text("detail", allow_empty=True),
    )


def decode_status_batch(data: bytes) -> StatusBatch:
    """Parse and check a status batch (JSON, zlib-compressed or not); raises :class:`EnvelopeError`."""
    obj = json_object(unpack_json(data, "status batch"), "status batch", data)
    get = Fields(obj, "status batch", data)
    events = obj.get("events")
    if not isinstance(events, list):
        raise EnvelopeError("status batch", "field 'events' must be a list", data)
    return StatusBatch(
        get.text("repeater"), get.text("site"), tuple(status_from_json(e, data) for e in events)
    )


def encode_status_ack(ack: StatusAck) -> bytes:
    """Compact JSON of ``ack``."""
    return json.dumps({"accepted": ack.accepted, "detail": ack.detail}, separators=(",", ":")).encode()


def decode_status_ack(data: bytes) -> StatusAck:
    """Parse and check the uplink's status ack; raises :class:`EnvelopeError` naming the field that is
    wrong."""
    get = Fields(json_object(data, "status ack", data), "status ack", data)
    return StatusAck(get.integer("accepted"), get.text("detail", allow_empty=True))
