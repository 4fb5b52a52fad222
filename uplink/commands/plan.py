"""One decoded command record -> what to send where (pure: no Kafka, no Zenoh, no clock).

* **command id**: the ``fleetlink-command-id`` header when present, else
  ``<topic>:<partition>:<offset>`` (the same after a re-delivery, so repeaters apply it once);
* **lease**: from the record's timestamp for the mapping's lease length; a record whose lease
  has already ended when the uplink reads it is not forwarded (it becomes an ``expired`` status);
* **targets**: the robots the mapping addresses, each at the site where it is registered, or
  at every site (a wildcard query) when its site is not known.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from fleetlink.uplink.commands.decode import DecodedValue
from fleetlink.uplink.commands.mapping import CommandMapping, targets
from fleetlink.wire.commands import CommandEnvelope
from fleetlink.wire.keys import ROOT, check_key_chunk, check_key_name, command_key

COMMAND_ID_HEADER = "fleetlink-command-id"


@dataclass(frozen=True, slots=True)
class CommandRecord:
    """A record read from a command topic."""

    topic: str
    partition: int
    offset: int
    key: bytes | None
    value: bytes | None
    headers: tuple[tuple[str, bytes], ...] = ()
    timestamp_ms: int = -1

    @property
    def source(self) -> str:
        """Where the record was read: ``<topic>:<partition>:<offset>``."""
        return f"{self.topic}:{self.partition}:{self.offset}"

    @property
    def text_key(self) -> str | None:
        """The key as text (undecodable UTF-8 replaced), or None for a null key."""
        return None if self.key is None else self.key.decode("utf-8", "replace")


@dataclass(frozen=True, slots=True)
class Forward:
    """Send ``envelope`` as a query on ``key_expr``; ``site`` None means every site."""

    site: str | None
    key_expr: str
    envelope: CommandEnvelope


def command_id(record: CommandRecord) -> str:
    """The command id: the ``fleetlink-command-id`` header (at most 1000 characters), else the record's
    source."""
    for name, value in record.headers:
        if name == COMMAND_ID_HEADER and value:
            text = value.decode("utf-8", "replace").strip()
            if text:
                return text[:1000]
    return record.source


def issued_at_ms(record: CommandRecord, now_ms: int) -> int:
    """The lease start: the record's timestamp (now, for a record that has none)."""
    return record.timestamp_ms if record.timestamp_ms > 0 else now_ms


def lease_until_ms(record: CommandRecord, mapping: CommandMapping, now_ms: int) -> int:
    """When the command's lease ends: its start plus the mapping's lease (ms since the epoch)."""
    return issued_at_ms(record, now_ms) + mapping.lease_ms


def any_site_key(robot: str, command: str) -> str:
    """``fleetlink/*/command/<robot>/<command>``: the command at every site's repeater."""
    check_key_name(robot, "robot")
    return f"{ROOT}/*/command/{robot}/{check_key_chunk(command, 'command')}"


def plan(
    record: CommandRecord,
    mapping: CommandMapping,
    decoded: DecodedValue,
    *,
    now_ms: int,
    site_of: Callable[[str], str | None],
    registered: Sequence[str] = (),
) -> list[Forward]:
    """The forwards for one record (raises ``RoutingError`` when it addresses no usable robot)."""
    issued = issued_at_ms(record, now_ms)
    cid = command_id(record)
    out: list[Forward] = []
    for target in targets(mapping, key=record.text_key, record=decoded.record, known_robots=registered):
        env = CommandEnvelope(
            command_id=cid,
            robot=target.robot,
            ros_topic=target.ros_topic,
            ros_type=mapping.type,
            mapping=mapping.name,
            issued_at_ms=issued,
            lease_until_ms=issued + mapping.lease_ms,
            period_ms=mapping.period_ms,
            schema_fp=decoded.writer.fingerprint,
            body=decoded.body,
            schema=decoded.writer.text,
            qos=mapping.qos_text,
            order=record.offset,
            source=record.source,
        )
        site = site_of(target.robot)
        if site:
            key = command_key(site, target.robot, mapping.name)
        else:
            key = any_site_key(target.robot, mapping.name)
        out.append(Forward(site, key, env))
    return out
