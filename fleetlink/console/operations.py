"""What an operator can do from the console beyond mappings, as small protocols the processes
fill in: the fleet console (the uplink) reads the dead-letter topic and sends commands through
Kafka; an edge's console has neither and says so.

- ``DeadLetters``: the newest dead letters (reason, stage, where the record was going, its raw
  bytes), optionally of one site; one record's raw bytes for download;
- ``Commands``: the command mappings an operator may use, sending one command (a record on the
  mapping's Kafka topic, keyed by the robot, the value Avro-encoded through the registry like
  any producer's), and the statuses the command router wrote for it (``delivered``,
  ``applied``, ``expired`` ...), read from the command status topic.
"""

from __future__ import annotations

from typing import Any, Protocol


class DeadLetters(Protocol):
    """Where the dead-letter browser reads (``KafkaDeadLetters`` on the uplink)."""

    def recent(self, site: str | None, limit: int) -> list[dict[str, Any]]:
        """Newest first: ``{partition, offset, timestamp_ms, key, site, edge, topic, stage, reason,
        size, value_hex}`` (``value_hex`` cut to the first 4 KiB)."""
        ...

    def raw(self, partition: int, offset: int) -> bytes | None:
        """One dead letter's value as it is in Kafka (``None``: no such record)."""
        ...


class Commands(Protocol):
    """What sends commands and reads their statuses (``KafkaCommands`` on the uplink)."""

    def mappings(self) -> list[dict[str, Any]]:
        """``{name, from, to, type, fields}`` per command mapping (``fields``: a value template)."""
        ...

    def send(self, mapping: str, robot: str, value: Any, *, user: str) -> dict[str, Any]:
        """Produce one command; ``{command_id, topic, partition, offset}`` once Kafka acknowledged
        it. Raises ``CommandRefusedError`` (its message says why) for an unknown mapping or robot, or a
        value that does not fit the mapping's type."""
        ...

    def statuses(self, command_ids: list[str]) -> dict[str, list[dict[str, Any]]]:
        """The status records of these commands, oldest first: ``{status, site, detail, at_ms}``."""
        ...


class CommandRefusedError(Exception):
    """A command the console will not send (the message is for the operator)."""
