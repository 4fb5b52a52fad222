"""The stage interface: what flows between stages (``Sample``) and what every stage offers.

A stage is a small class with explicit state and no clock of its own: ``process`` and ``tick``
receive the current processing time ``now_ns``. Stages never mutate a sample's value; a stage
that changes the value emits a new ``Sample`` with ``raw=None``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, Protocol, runtime_checkable


@dataclass(frozen=True, slots=True)
class Sample:
    """One decoded message on its way through a mapping's stages."""

    robot: str
    """Robot name, e.g. ``tb4_01``."""
    topic: str
    """Source ROS topic, e.g. ``/tb4_01/odom``."""
    stamp_ns: int
    """Source timestamp (ns since the epoch): the event time."""
    value: Mapping[str, Any]
    """The message as an Avro-datum-shaped dict (nested dicts; numeric arrays as lists or numpy
    arrays; ``bytes`` for ``uint8[]``)."""
    raw: bytes | None = None
    """The original CDR while the value is untouched (enables a fast encode path)."""


@dataclass(slots=True)
class StageCounters:
    """What a stage did, in samples. For every stage, at any time::

        received == passed + dropped + late + errors + held

    where ``held`` is the number of samples the stage is holding for later (``throttle`` with
    ``keep: latest``, a suppressed ``on_change`` sample kept as the next heartbeat).
    ``emitted`` counts outputs, which are not always inputs (aggregate records, heartbeats).
    ``nan`` counts NaN values an ``aggregate`` skipped (values, not samples).
    """

    received: int = 0
    passed: int = 0
    dropped: int = 0
    late: int = 0
    errors: int = 0
    emitted: int = 0
    nan: int = 0

    def as_dict(self) -> dict[str, int]:
        """The counters by field name."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


@runtime_checkable
class Stage(Protocol):
    """One step of a mapping's pipeline."""

    name: str
    counters: StageCounters

    def process(self, sample: Sample, now_ns: int) -> list[Sample]:
        """Feed one sample; returns what the stage emits now (possibly nothing). Never raises
        for a bad sample: it is counted in ``counters.errors`` and dropped."""
        ...

    def tick(self, now_ns: int) -> list[Sample]:
        """Time-driven output (heartbeats, held samples, windows closed by an idle timeout)."""
        ...

    def output_schema(self, input_schema: dict[str, Any]) -> dict[str, Any]:
        """The Avro schema of what the stage emits given the schema it receives. Raises
        ``StageConfigError`` (naming the field path) when the stage does not fit the type."""
        ...
