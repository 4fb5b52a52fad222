"""Registration records from a site -> checked -> the uplink's own record on the registrations topic.

The edge sends each robot (de)registration as an Avro ``RobotEvent`` on the registrations
topic. The uplink never copies that value: it decodes it with the schema it knows, checks that
the event names the site and edge the batch came from and the record's key, that the names are
usable, and that the site may (de)register the robot (``commands.ownership``, applied to the
shared ``RobotDirectory`` at once, so the next batch sees it); then it writes a record of its
own: the event encoded again, registered under the topic's subject by the uplink, headers it
sets, and its own clock as the Kafka timestamp (the ownership rule's time).
"""

from __future__ import annotations

import copy
import io
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import fastavro

from fleetlink.common.names import key_chunk_problem, key_path_problem
from fleetlink.schemas.errors import RegistryError
from fleetlink.schemas.registry import RegistryUnavailableError, subject_for_topic
from fleetlink.schemas.single_object import confluent_frame, fingerprint
from fleetlink.uplink.commands.directory import RobotDirectory
from fleetlink.uplink.identity import Source
from fleetlink.wire import Record
from fleetlink.wire.robot_events import EDGE_HEADER, EVENT_SCHEMA, ROBOT_HEADER, SITE_HEADER

EVENT_FINGERPRINT = fingerprint(EVENT_SCHEMA)
_PARSED = fastavro.parse_schema(copy.deepcopy(EVENT_SCHEMA))
_MAX_TEXT = 200


class Registry(Protocol):
    """The schema registry call the registration writer makes."""

    def register(self, subject: str, schema: dict[str, Any]) -> int:
        """Register ``schema`` under ``subject`` (or find it there); returns the schema id."""


class RegistrationUnavailableError(Exception):
    """The registry could not register the event schema now: the edge sends the batch again."""


@dataclass(frozen=True, slots=True)
class Rebuilt:
    """The record the uplink writes for one accepted registration."""

    key: bytes
    value: bytes
    headers: list[tuple[str, bytes]]
    timestamp_ms: int


class RegistrationWriter:
    """Checks the (de)registrations a site sends, claims the robot in the directory, and makes the uplink's
    own record of each accepted one."""

    def __init__(
        self,
        registry: Registry,
        topic: str,
        directory: RobotDirectory,
        *,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self._registry = registry
        self.topic = topic
        self.directory = directory
        self._clock = clock
        self._schema_id: int | None = None
        self._lock = threading.Lock()

    def rebuild(self, source: Source, record: Record) -> Rebuilt | str:
        """The record to write for ``record``, or why it is refused (raises
        ``RegistrationUnavailableError`` when the registry cannot be reached)."""
        datum = _decode(record)
        if isinstance(datum, str):
            return datum
        problem = _content_problem(source, record, datum)
        if problem is not None:
            return problem
        robot: str = datum["robot"]
        now_ms = int(self._clock() * 1000)
        schema_id = self._event_schema_id()
        problem = self.directory.claim(
            robot, source.site, registered=datum["event"] == "registered", now_ms=now_ms
        )
        if problem is not None:
            return f"robot {robot!r}: {problem}"
        out = io.BytesIO()
        fastavro.schemaless_writer(out, _PARSED, datum)
        return Rebuilt(
            key=robot.encode(),
            value=confluent_frame(schema_id, out.getvalue()),
            headers=[
                (SITE_HEADER, source.site.encode()),
                (ROBOT_HEADER, robot.encode()),
                (EDGE_HEADER, source.edge_id.encode()),
            ],
            timestamp_ms=now_ms,
        )

    def _event_schema_id(self) -> int:
        with self._lock:
            if self._schema_id is None:
                try:
                    self._schema_id = self._registry.register(subject_for_topic(self.topic), EVENT_SCHEMA)
                except RegistryUnavailableError as exc:
                    raise RegistrationUnavailableError(str(exc)) from None
                except RegistryError as exc:
                    raise RegistrationUnavailableError(
                        f"the registry refused the event schema: {exc}"
                    ) from None
            return self._schema_id


def _decode(record: Record) -> dict[str, Any] | str:
    """The event datum of a registration record, or why it is not one."""
    if record.raw_value or record.fingerprint != EVENT_FINGERPRINT:
        return "a registration must be a fleetlink RobotEvent in Avro single-object encoding"
    try:
        datum = fastavro.schemaless_reader(io.BytesIO(record.value[10:]), _PARSED, None)
    except (ValueError, TypeError, EOFError, IndexError, UnicodeDecodeError) as exc:
        return f"the registration does not decode as a RobotEvent: {exc}"
    if not isinstance(datum, dict):
        return "the registration does not decode as a RobotEvent"
    return datum


def _content_problem(source: Source, record: Record, datum: dict[str, Any]) -> str | None:
    robot, robot_type = datum.get("robot"), datum.get("robot_type")
    if datum.get("site") != source.site or datum.get("edge_id") != source.edge_id:
        return f"the registration names {datum.get('site')!r}/{datum.get('edge_id')!r} but came from {source}"
    if not isinstance(robot, str) or key_path_problem(robot) is not None or len(robot) > _MAX_TEXT:
        return f"robot name {robot!r} is not usable"
    if record.key != robot.encode():
        return f"the record's key is not the robot's name {robot!r}"
    if not isinstance(robot_type, str) or key_chunk_problem(robot_type) is not None:
        return f"robot type {robot_type!r} is not usable"
    reason = datum.get("reason")
    if not isinstance(reason, str) or len(reason) > _MAX_TEXT:
        return "the registration's reason is not a short text"
    return None
