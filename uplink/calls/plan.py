"""One decoded request, goal or cancel record -> the call envelope and where it goes (pure).

* **correlation id** (services): the ``fleetlink-correlation-id`` header, else
  ``<topic>:<partition>:<offset>``; **goal id** (actions): the ``fleetlink-goal-id`` header (a
  UUID), else a UUID made from ``<topic>:<partition>:<offset>`` (the same after a re-delivery,
  so the site makes each call once); a cancel names its goal in ``goal_id`` or its key;
* **deadline**: the record's timestamp + the mapping's ``timeout`` (a cancel: + 10 s);
* **where**: the robot's site; a robot no site holds gets no call (the outcome says so).
"""

from __future__ import annotations

import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from fleetlink.common.names import key_path_problem
from fleetlink.uplink.calls.mapping import ActionMapping, CallMapping, ServiceMapping
from fleetlink.uplink.commands.errors import RoutingError
from fleetlink.uplink.commands.mapping import resolve
from fleetlink.uplink.commands.plan import CommandRecord, issued_at_ms
from fleetlink.wire.calls import CallEnvelope, CallKind, call_key

CORRELATION_HEADER = "fleetlink-correlation-id"
GOAL_HEADER = "fleetlink-goal-id"
CANCEL_TIMEOUT_MS = 10_000
_GOAL_NAMESPACE = uuid.UUID("5a0f3c1e-6f1b-4c55-9d3e-1f0e8b7a2c44")


@dataclass(frozen=True, slots=True)
class CallForward:
    """Send ``envelope`` as a query on ``key_expr``; ``site`` None: the robot has no known site."""

    site: str | None
    key_expr: str
    envelope: CallEnvelope


def _header(record: CommandRecord, name: str) -> str | None:
    for key, value in record.headers:
        if key == name and value:
            text = value.decode("utf-8", "replace").strip()
            if text:
                return text
    return None


def correlation_id(record: CommandRecord) -> str:
    """A service call's id: the ``fleetlink-correlation-id`` header, else the record's source (at most 200
    characters)."""
    return (_header(record, CORRELATION_HEADER) or record.source)[:200]


def goal_id(record: CommandRecord) -> str:
    """A goal's id: the ``fleetlink-goal-id`` header as a UUID, else a UUID made from the record's source;
    ``RoutingError`` when the header is no UUID."""
    given = _header(record, GOAL_HEADER)
    if given is not None:
        try:
            return str(uuid.UUID(given))
        except ValueError:
            raise RoutingError(f"header {GOAL_HEADER} {given[:60]!r} is not a UUID") from None
    return str(uuid.uuid5(_GOAL_NAMESPACE, record.source))


def cancel_target(record: CommandRecord, value: Mapping[str, Any]) -> tuple[str, str]:
    """(goal id, robot) of a cancel record."""
    robot = value.get("robot")
    if not isinstance(robot, str) or not robot:
        raise RoutingError("a cancel record needs a 'robot' string field")
    given = value.get("goal_id") or record.text_key
    if not isinstance(given, str) or not given:
        raise RoutingError("a cancel record needs its goal id in 'goal_id' or in its key")
    try:
        return str(uuid.UUID(given.strip())), robot
    except ValueError:
        raise RoutingError(f"goal id {given[:60]!r} is not a UUID") from None


def robot_of(mapping: CallMapping, record: CommandRecord, value: Mapping[str, Any]) -> str:
    """The robot a request or goal record addresses, by the mapping's ``robot``; ``RoutingError`` when it
    names none."""
    return resolve(mapping.robot_ref, key=record.text_key, robot=None, record=value)


def plan_call(
    kind: CallKind,
    record: CommandRecord,
    mapping: ServiceMapping | ActionMapping,
    value: Mapping[str, Any],
    payload: bytes,
    *,
    now_ms: int,
    site_of: Callable[[str], str | None],
) -> CallForward:
    """The forward of a request (``service``), goal (``goal``) or cancel (``cancel``) record;
    raises ``RoutingError`` when it addresses no usable robot or goal."""
    issued = issued_at_ms(record, now_ms)
    if kind == "cancel":
        call_id, robot = cancel_target(record, value)
        deadline = issued + CANCEL_TIMEOUT_MS
    else:
        robot = robot_of(mapping, record, value)
        call_id = correlation_id(record) if kind == "service" else goal_id(record)
        deadline = issued + mapping.timeout_ms
    problem = key_path_problem(robot)
    if problem is not None:
        raise RoutingError(f"robot {robot!r} {problem}")
    name = mapping.to_template.render(key=record.text_key, robot=robot, record=value)
    env = CallEnvelope(
        kind, call_id, robot, name, mapping.type, mapping.name, issued, deadline, payload, record.source
    )
    site = site_of(robot)
    return CallForward(site, call_key(site, robot, mapping.name) if site else "", env)
