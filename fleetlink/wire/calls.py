"""The wire contract of ROS 2 service calls and action goals over the WAN (pure: bytes in, bytes out).

Cloud -> site, the uplink's query on ``fleetlink/<site>/call/<robot>/<mapping>`` (signed like a
command, ``fleetlink.wire.command_auth``; the repeater answers with a command reply, JSON)::

    "FLK" | version (1) | flags (bit 0: zlib) | rest
    rest = u32 header length (big-endian) | header (JSON, UTF-8) | payload (CDR)

``kind`` says what the envelope asks: ``service`` (call ``name`` with the CDR request),
``goal`` (send the CDR ``Name_Goal`` to action ``name`` under goal id ``id``) or ``cancel``
(cancel goal ``id``; no payload). ``deadline`` ends the call: a service not answered by then
is a ``timeout``, a goal still running is canceled and reported ``timeout``.

Site -> cloud, the repeater's query on ``fleetlink/<site>/call-outcome/<repeater>``: a batch of
:class:`Outcome` (JSON, zlib when larger than 160 bytes); the uplink produces each to the
mapping's Kafka topic and answers with a status ack (``fleetlink.wire.commands.StatusAck``)
once Kafka has them. Every decoder checks every field and raises
:class:`~fleetlink.wire.errors.EnvelopeError` naming it.
"""

from __future__ import annotations

import base64
import binascii
from dataclasses import dataclass, field
from typing import Any, Literal, get_args

from fleetlink.common.names import ros_action_type_problem, ros_service_type_problem, ros_topic_problem
from fleetlink.wire.envelope import (
    COMPRESS_ABOVE,
    MAX_ENVELOPE,
    Fields,
    json_object,
    pack_envelope,
    pack_json,
    unpack_envelope,
    unpack_json,
)
from fleetlink.wire.errors import EnvelopeError, WireError
from fleetlink.wire.keys import check_key_chunk, check_key_name, site_prefix

MAGIC = b"FLK"
MAX_ID = 200

CallKind = Literal["service", "goal", "cancel"]
CALL_KINDS: frozenset[str] = frozenset(get_args(CallKind))

OutcomeKind = Literal["reply", "feedback", "result", "cancel"]
OUTCOME_KINDS: frozenset[str] = frozenset(get_args(OutcomeKind))

ReplyStatus = Literal["ok", "timeout", "unavailable", "error", "expired", "rejected"]
GoalState = Literal[
    "accepted", "rejected", "succeeded", "canceled", "aborted", "timeout", "unavailable", "error", "expired"
]
CancelState = Literal[
    "cancel-accepted",
    "cancel-rejected",
    "cancel-unknown-goal",
    "cancel-terminated",
    "cancel-unavailable",
    "cancel-timeout",
    "cancel-error",
]
STATUSES: dict[str, frozenset[str]] = {
    "reply": frozenset(get_args(ReplyStatus)),
    "feedback": frozenset({"feedback"}),
    "result": frozenset(get_args(GoalState)),
    "cancel": frozenset(get_args(CancelState)),
}
"""The statuses each outcome kind may carry."""

FINAL_GOAL_STATES: frozenset[str] = STATUSES["result"] - {"accepted"}


def call_key(site: str, robot: str, mapping: str) -> str:
    """Calls for one robot: ``fleetlink/<site>/call/<robot>/<mapping>``."""
    robot = check_key_name(robot, "robot")
    return f"{site_prefix(site)}/call/{robot}/{check_key_chunk(mapping, 'mapping')}"


def outcome_key(site: str, repeater_id: str) -> str:
    """Where a repeater sends outcomes: ``fleetlink/<site>/call-outcome/<repeater>``."""
    return f"{site_prefix(site)}/call-outcome/{check_key_chunk(repeater_id, 'repeater')}"


@dataclass(frozen=True, slots=True)
class CallEnvelope:
    """What the uplink asks a robot's site: call a ROS service, send an action goal or cancel a goal, by
    its deadline."""

    kind: CallKind
    call_id: str
    """The request's correlation id (service) or the goal id as a UUID text (goal, cancel)."""
    robot: str
    ros_name: str
    """The ROS service or action name (``/tb4_01/e_stop``, ``/tb4_01/dock``)."""
    ros_type: str
    """``pkg/srv/Name`` or ``pkg/action/Name``."""
    mapping: str
    issued_at_ms: int
    """The Kafka record's timestamp."""
    deadline_ms: int
    payload: bytes = b""
    """CDR: the service request or the action's ``Name_Goal``; empty for a cancel."""
    source: str = ""
    """``<topic>:<partition>:<offset>`` of the Kafka record."""


@dataclass(frozen=True, slots=True)
class Outcome:
    """What became of a call, as a repeater reports it: a service reply, a goal's feedback or result, or a
    cancel's answer."""

    kind: OutcomeKind
    call_id: str
    robot: str
    mapping: str
    status: str
    at_ms: int
    detail: str = ""
    payload: bytes | None = None
    """CDR: the service response, the action's ``Name_Feedback`` or ``Name_Result``."""
    issued_at_ms: int = 0
    """When the call's Kafka record was written (so replies can show the round trip)."""
    site: str = ""


@dataclass(frozen=True, slots=True)
class OutcomeBatch:
    """The outcomes one repeater of ``site`` sends the uplink in one query."""

    repeater: str
    site: str
    outcomes: tuple[Outcome, ...] = field(default_factory=tuple)


# -- call envelope --------------------------------------------------------------------------


def call_fields(env: CallEnvelope) -> dict[str, Any]:
    """The header fields of ``env`` but its source (the repeater's journal keeps the same)."""
    return {
        "kind": env.kind,
        "id": env.call_id,
        "robot": env.robot,
        "name": env.ros_name,
        "type": env.ros_type,
        "mapping": env.mapping,
        "issued": env.issued_at_ms,
        "deadline": env.deadline_ms,
    }


def encode_call(env: CallEnvelope, *, compress_above: int = COMPRESS_ABOVE) -> bytes:
    """Check ``env`` and pack it as an ``FLK`` envelope, zlib-compressed when larger than
    ``compress_above`` bytes and smaller so."""
    check_call(env)
    header = call_fields(env)
    if env.source:
        header["source"] = env.source
    return pack_envelope(MAGIC, header, env.payload, compress_above=compress_above)


def decode_call(data: bytes) -> CallEnvelope:
    """Parse and check a call envelope; raises :class:`EnvelopeError` naming the field that is wrong."""
    what = "call envelope"
    header, payload = unpack_envelope(data, MAGIC, what)
    get = Fields(header, what, data)
    kind = get.text("kind")
    if kind not in CALL_KINDS:
        raise EnvelopeError(what, f"kind {kind!r} is not one of {sorted(CALL_KINDS)}", data)
    env = CallEnvelope(
        kind=kind,  # type: ignore[arg-type]
        call_id=get.text("id"),
        robot=get.text("robot"),
        ros_name=get.text("name"),
        ros_type=get.text("type"),
        mapping=get.text("mapping"),
        issued_at_ms=get.integer("issued"),
        deadline_ms=get.integer("deadline"),
        payload=payload,
        source=get.text("source", allow_empty=True),
    )
    try:
        check_call(env)
    except EnvelopeError as exc:
        raise EnvelopeError(what, exc.reason, data) from None
    return env


def check_call(env: CallEnvelope) -> None:
    """Raise :class:`EnvelopeError` unless every field of ``env`` is usable."""

    def bad(reason: str) -> EnvelopeError:
        return EnvelopeError("call envelope", reason)

    if env.kind not in CALL_KINDS:
        raise bad(f"kind {env.kind!r} is not one of {sorted(CALL_KINDS)}")
    if not env.call_id or len(env.call_id) > MAX_ID:
        raise bad(f"call id must have 1 to {MAX_ID} characters")
    try:
        check_key_name(env.robot, "robot")
        check_key_chunk(env.mapping, "mapping")
    except WireError as exc:
        raise bad(str(exc)) from None
    problem = ros_topic_problem(env.ros_name)
    if problem is not None:
        raise bad(f"ROS name {env.ros_name!r}: {problem}")
    type_problem = ros_service_type_problem if env.kind == "service" else ros_action_type_problem
    problem = type_problem(env.ros_type)
    if problem is not None:
        raise bad(f"a {env.kind} envelope's ROS type {env.ros_type!r} {problem}")
    if env.issued_at_ms < 0 or env.deadline_ms < env.issued_at_ms:
        raise bad(f"[{env.issued_at_ms}, {env.deadline_ms}] ms is not a time span")
    if env.kind == "cancel" and env.payload:
        raise bad("a cancel carries no payload")
    if env.kind != "cancel" and len(env.payload) < 4:
        raise bad(f"a {env.kind} carries a CDR payload (at least its 4-byte header)")


# -- outcomes -------------------------------------------------------------------------------


def outcome_to_json(out: Outcome) -> dict[str, Any]:
    """The JSON object of ``out``: empty optional fields left out, the CDR payload as base64."""
    obj: dict[str, Any] = {
        "kind": out.kind,
        "id": out.call_id,
        "robot": out.robot,
        "mapping": out.mapping,
        "status": out.status,
        "at": out.at_ms,
    }
    if out.detail:
        obj["detail"] = out.detail
    if out.payload is not None:
        obj["cdr"] = base64.b64encode(out.payload).decode()
    if out.issued_at_ms:
        obj["issued"] = out.issued_at_ms
    if out.site:
        obj["site"] = out.site
    return obj


def outcome_from_json(obj: object, data: bytes = b"") -> Outcome:
    """Read and check one outcome's JSON object; ``data`` is the whole message, quoted in errors
    (:class:`EnvelopeError`)."""
    if not isinstance(obj, dict):
        raise EnvelopeError("outcome", "not a JSON object", data)
    get = Fields(obj, "outcome", data)
    kind = get.text("kind")
    if kind not in OUTCOME_KINDS:
        raise EnvelopeError("outcome", f"kind {kind!r} is not one of {sorted(OUTCOME_KINDS)}", data)
    status = get.text("status")
    if status not in STATUSES[kind]:
        raise EnvelopeError("outcome", f"status {status!r} is not one of {sorted(STATUSES[kind])}", data)
    cdr = get.optional_text("cdr")
    payload = None
    if cdr is not None:
        try:
            payload = base64.b64decode(cdr, validate=True)
        except (binascii.Error, ValueError):
            raise EnvelopeError("outcome", "field 'cdr' is not base64", data) from None
    out = Outcome(
        kind,  # type: ignore[arg-type]
        get.text("id"),
        get.text("robot"),
        get.text("mapping"),
        status,
        get.integer("at"),
        get.text("detail", allow_empty=True),
        payload,
        get.integer("issued") if "issued" in obj else 0,
        get.text("site", allow_empty=True),
    )
    check_outcome(out, data)
    return out


def check_outcome(out: Outcome, data: bytes = b"") -> None:
    """Raise :class:`EnvelopeError` unless every field of ``out`` is usable (``data`` is quoted in the
    error)."""
    if out.kind not in OUTCOME_KINDS:
        raise EnvelopeError("outcome", f"kind {out.kind!r} is not one of {sorted(OUTCOME_KINDS)}", data)
    if out.status not in STATUSES[out.kind]:
        raise EnvelopeError(
            "outcome", f"status {out.status!r} is not one of {sorted(STATUSES[out.kind])}", data
        )
    if not out.call_id or len(out.call_id) > MAX_ID:
        raise EnvelopeError("outcome", f"call id must have 1 to {MAX_ID} characters", data)
    try:
        check_key_name(out.robot, "robot")
        check_key_chunk(out.mapping, "mapping")
    except WireError as exc:
        raise EnvelopeError("outcome", str(exc), data) from None
    if out.kind == "feedback" and out.payload is None:
        raise EnvelopeError("outcome", "feedback carries the feedback's CDR", data)


def encode_outcomes(batch: OutcomeBatch, *, compress_above: int = COMPRESS_ABOVE) -> bytes:
    """JSON, zlib-compressed when larger than ``compress_above`` bytes (JSON starts with ``{``)."""
    for out in batch.outcomes:
        check_outcome(out)
    return pack_json(
        {
            "repeater": batch.repeater,
            "site": batch.site,
            "outcomes": [outcome_to_json(o) for o in batch.outcomes],
        },
        compress_above=compress_above,
    )


def decode_outcomes(data: bytes) -> OutcomeBatch:
    """Parse and check an outcome batch (JSON, zlib-compressed or not); raises :class:`EnvelopeError`."""
    raw = unpack_json(data, "outcome batch")
    if len(raw) > MAX_ENVELOPE:
        raise EnvelopeError("outcome batch", f"larger than {MAX_ENVELOPE} bytes", data)
    obj = json_object(raw, "outcome batch", data)
    get = Fields(obj, "outcome batch", data)
    outcomes = obj.get("outcomes")
    if not isinstance(outcomes, list):
        raise EnvelopeError("outcome batch", "field 'outcomes' must be a list", data)
    return OutcomeBatch(
        get.text("repeater"), get.text("site"), tuple(outcome_from_json(o, data) for o in outcomes)
    )
