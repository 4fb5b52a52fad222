"""What the admin API needs from the running edge: the ``AdminBackend`` protocol.

The edge agent provides it (``edge.admin.table_backend.TableBackend`` implements it over a
``MappingTable`` and a ``GraphWatcher``, with hooks for the agent's counters and state). The
admin service never reaches into the agent otherwise.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

from fleetlink.common.metrics.buckets import EMPTY, BucketTotals
from fleetlink.edge.config import EdgeConfig
from fleetlink.edge.mapping import MappingSpec, MappingTable, RobotTypeSpec
from fleetlink.edge.spool import SpoolStats
from fleetlink.roswire.graph import TopicInfo

RobotState = Literal["registered", "lost"]


@dataclass(frozen=True, slots=True)
class RobotStatus:
    """One robot known to the edge: its robot type, state and how it came to be registered."""

    robot: str
    robot_type: str
    registered_at: float | None = None
    """Wall-clock seconds since the epoch; ``None`` when not known."""
    state: RobotState = "registered"
    """``lost``: its liveliness is gone, it is deregistered when the grace period ends."""
    explicit: bool = False
    """Registered on the registration topic rather than discovered."""
    history: tuple[RobotEvent, ...] = ()
    """The robot's last registrations and deregistrations at this edge, oldest first."""


@dataclass(frozen=True, slots=True)
class RobotEvent:
    """One registration or deregistration of a robot at this edge."""

    event: str
    robot_type: str
    reason: str
    at: float
    """Wall-clock seconds since the epoch."""


@dataclass(frozen=True, slots=True)
class MappingCounts:
    """One mapping's running totals (``edge.runtime.records.MappingCounters`` + its stages')."""

    received: int = 0
    emitted: int = 0
    dropped: int = 0
    dead_lettered: int = 0
    type_mismatch: int = 0
    stages: Mapping[str, Mapping[str, int]] = field(default_factory=dict)
    """Stage name -> ``StageCounters.as_dict()`` (received, passed, dropped, late, errors, emitted, nan)."""


@dataclass(frozen=True, slots=True)
class MappingIssue:
    """Something the runtime found wrong with a mapping (it keeps running, degraded)."""

    reason: str
    """``unknown_type`` (a ROS type not in the type store), ``setup`` (stages do not fit the type)."""
    detail: str


@dataclass(frozen=True, slots=True)
class BufferState:
    """One record buffer's spool statistics next to its configured capacity."""

    stats: SpoolStats
    capacity_bytes: int
    appended_bytes: int = 0
    """Running total of payload bytes appended, when the agent counts it (0 otherwise)."""


@dataclass(frozen=True, slots=True)
class WanTotals:
    """One WAN sender's running totals (``edge.runtime.sender.SenderStats``)."""

    batches_sent: int = 0
    records_sent: int = 0
    bytes_sent: int = 0
    batches_acked: int = 0
    records_acked: int = 0
    batches_retried: int = 0
    in_flight: int = 0
    ack_latency: BucketTotals = EMPTY
    """From sending each acknowledged batch to its ack, counted per bucket."""


@dataclass(frozen=True, slots=True)
class IntakeState:
    """Between receipt and spool: what waits, for how long, what was dropped; the memory."""

    dropped: int = 0
    queued: int = 0
    max_samples: int = 0
    lag_s: float = 0.0
    lag_alarm_s: float = 0.0
    """0: no alarm set."""
    rss_bytes: int = 0
    bound_bytes: int = 0
    """0: not known."""


@dataclass(frozen=True, slots=True)
class EdgeSnapshot:
    """The agent's state at one moment, for counters, gauges and health. Every field has a
    neutral default so an agent can fill in what it has."""

    mappings: Mapping[str, MappingCounts] = field(default_factory=dict)
    issues: Mapping[str, Sequence[MappingIssue]] = field(default_factory=dict)
    buffers: Sequence[BufferState] = ()
    wan_link_up: bool | None = None
    """``None``: not known yet (nothing sent so far)."""
    wan: Mapping[str, WanTotals] = field(default_factory=dict)
    """Stream -> its sender's totals."""
    sequence_gaps: Mapping[str, int] = field(default_factory=dict)
    """ROS topic -> messages missing so far (running total)."""
    unmapped: Mapping[str, int] = field(default_factory=dict)
    """ROS topic -> samples received that no mapping took (running total)."""
    failure: str | None = None
    """Set when the agent cannot do its job (spool unwritable, a worker thread died)."""
    lost_before_spool: Mapping[str, Mapping[str, int]] = field(default_factory=dict)
    """Robot -> ROS topic -> samples that never reached the spool because the edge was stopped or
    crashed (running total since start, counted from each publisher's first sample)."""
    spool_damage: Mapping[str, Sequence[Mapping[str, Any]]] = field(default_factory=dict)
    """Stream -> the damage findings awaiting an operator's acknowledgement."""
    intake: IntakeState = field(default_factory=IntakeState)


class AdminBackend(Protocol):
    """The running edge, as the admin API sees it."""

    def install(
        self, config: EdgeConfig, robot_types: Sequence[RobotTypeSpec], mappings: Sequence[MappingSpec]
    ) -> None:
        """Make ``config``'s declarations live, atomically (``MappingTable.reload``), then register
        robots the new robot types match and subscribe to topics new mappings match."""
        ...

    def mapping_table(self) -> MappingTable:
        """The live table (``list``, ``match``, ``robots``)."""
        ...

    def topics(self) -> Mapping[str, TopicInfo]:
        """The discovered ROS topics (``GraphWatcher.topics()``)."""
        ...

    def robots(self) -> Sequence[RobotStatus]:
        """Every robot the edge knows, with its state and registration history."""
        ...

    def snapshot(self) -> EdgeSnapshot:
        """The edge's counters and state now."""
        ...

    def spool_damage(self) -> Sequence[Mapping[str, Any]]:
        """Every damage finding of the durable spool (``edge.spool.damage``), acknowledged or not."""
        ...

    def acknowledge_spool_damage(self) -> Sequence[Mapping[str, Any]]:
        """Acknowledge the durable spool's damage findings; returns those that were waiting."""
        ...
