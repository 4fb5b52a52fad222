"""Errors raised by the edge agent's building blocks (mapping engine, spool, config).

Config-time problems are ``ConfigError`` subclasses so ``fleetlink validate`` and the config
loader report them like any other config mistake. Per-record problems (a message field that
renders an illegal Kafka topic) are ``RenderError``: the caller dead-letters the record and
carries on. Spool errors carry the file and offset they are about.
"""

from __future__ import annotations

from pathlib import Path

from fleetlink.common.errors import ConfigError, FleetlinkError


class EdgeError(FleetlinkError):
    """Base class of the edge agent's errors."""


class MappingError(ConfigError, EdgeError):
    """A mapping, topic pattern or template is invalid (raised at config or admin time).

    ``mapping`` and ``template`` name what is wrong, when known.
    """

    def __init__(self, message: str, *, mapping: str | None = None, template: str | None = None) -> None:
        prefix = f"mapping {mapping!r}: " if mapping else ""
        super().__init__(prefix + message)
        self.mapping = mapping
        self.template = template


class RenderError(EdgeError):
    """One record cannot be mapped: a template needs a message field that is missing or
    unusable, or the rendered Kafka topic is illegal. The record goes to the dead-letter topic."""

    def __init__(self, message: str, *, mapping: str, template: str, value: str | None = None) -> None:
        super().__init__(f"mapping {mapping!r}, template {template!r}: {message}")
        self.mapping = mapping
        self.template = template
        self.value = value


class SpoolError(EdgeError):
    """The spool cannot do what was asked (I/O failure, bad directory, misuse)."""

    def __init__(self, message: str, *, path: Path | None = None, offset: int | None = None) -> None:
        where = ""
        if path is not None:
            where = f" [{path}" + (f" @ offset {offset}" if offset is not None else "") + "]"
        super().__init__(message + where)
        self.path = path
        self.offset = offset


class SpoolFullError(SpoolError):
    """The spool is at ``max_bytes`` (or the disk is full) and, under the ``block`` policy, no
    room was freed within the timeout. The record was NOT taken: the caller still owns it.
    ``taken`` says how many leading records of an ``append_many`` call were taken."""

    def __init__(self, message: str, *, path: Path | None = None, taken: int = 0) -> None:
        super().__init__(message, path=path)
        self.taken = taken


class SpoolLockedError(SpoolError):
    """Another process (or another ``Spool`` in this process) has the spool directory open."""


class SpoolClosedError(SpoolError):
    """The spool was used after ``close()``."""
