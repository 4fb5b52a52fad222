"""``AgentBackend``: the admin API's view of a started ``EdgeAgent``, through its public API.

Counters come from ``EdgeAgent.snapshot()`` (``snapshot_from_agent`` reads that dict, pure; it
also takes ``issues`` — ``{mapping: [{"reason", "detail"}]}`` — and ``robot_details`` when the
agent reports them);
the ROS graph from a ``GraphWatcher`` of its own on the agent's session (started in ``start``);
changes go through ``EdgeAgent.reload`` (the mapping table swap plus a subscription refresh).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from types import TracebackType
from typing import TYPE_CHECKING, Any

from fleetlink.common.metrics.buckets import EMPTY, BucketTotals
from fleetlink.edge.admin.backend import (
    BufferState,
    EdgeSnapshot,
    IntakeState,
    MappingCounts,
    MappingIssue,
    RobotEvent,
    RobotState,
    RobotStatus,
    WanTotals,
)
from fleetlink.edge.config import EdgeConfig
from fleetlink.edge.mapping import MappingSpec, MappingTable, RobotTypeSpec
from fleetlink.edge.spool import SpoolStats
from fleetlink.roswire.discovery import GraphWatcher
from fleetlink.roswire.graph import TopicInfo

if TYPE_CHECKING:
    from fleetlink.edge.agent import EdgeAgent

_COUNTS = ("received", "emitted", "dropped", "dead_lettered", "type_mismatch")
_WAN = (
    "batches_sent",
    "records_sent",
    "bytes_sent",
    "batches_acked",
    "records_acked",
    "batches_retried",
    "in_flight",
)


def _int(value: Any) -> int:
    return int(value) if isinstance(value, int | float) and not isinstance(value, bool) else 0


def _dict(value: Any) -> Mapping[str, Any]:
    return value if isinstance(value, Mapping) else {}


def _buckets(value: Any) -> BucketTotals:
    data = _dict(value)
    counts = data.get("counts")
    if not isinstance(counts, list) or len(counts) != len(EMPTY.counts):
        return EMPTY
    total = data.get("sum_s")
    return BucketTotals(
        tuple(_int(c) for c in counts), float(total) if isinstance(total, int | float) else 0.0
    )


def snapshot_from_agent(data: Mapping[str, Any], config: EdgeConfig) -> EdgeSnapshot:
    """``EdgeAgent.snapshot()`` (plain data) -> ``EdgeSnapshot``; missing parts stay neutral."""
    stages = _dict(data.get("stages"))
    mappings = {
        str(name): MappingCounts(
            **{k: _int(_dict(counts).get(k)) for k in _COUNTS},
            stages={
                str(s): {str(k): _int(v) for k, v in _dict(c).items()}
                for s, c in _dict(stages.get(name)).items()
            },
        )
        for name, counts in _dict(data.get("mappings")).items()
    }
    capacity = {"durable": int(config.spool.max_bytes), "memory": int(config.memory.max_bytes)}
    buffers, wan, healthy = [], {}, []
    damage: dict[str, list[Mapping[str, Any]]] = {}
    for stream, entry in _dict(data.get("streams")).items():
        found = _dict(entry).get("damage")
        if isinstance(found, list) and found:
            damage[str(stream)] = [f for f in found if isinstance(f, Mapping)]
        buffer = _dict(_dict(entry).get("buffer"))
        if buffer:
            fields: dict[str, Any] = {k: buffer[k] for k in SpoolStats.__dataclass_fields__ if k in buffer}
            try:
                stats = SpoolStats(**fields)
            except TypeError:
                stats = None
            if stats is not None:
                buffers.append(BufferState(stats=stats, capacity_bytes=capacity.get(str(stream), 0)))
        sender = _dict(_dict(entry).get("sender"))
        if sender:
            wan[str(stream)] = WanTotals(
                **{k: _int(sender.get(k)) for k in _WAN}, ack_latency=_buckets(sender.get("ack_latency"))
            )
            healthy.append(bool(sender.get("healthy", True)))
    subscriptions = _dict(data.get("subscriptions"))
    gaps = {str(topic): _int(_dict(sub).get("missing")) for topic, sub in subscriptions.items()}
    unmapped = {str(topic): _int(_dict(sub).get("unmapped")) for topic, sub in subscriptions.items()}
    issues = {
        str(name): [
            MappingIssue(reason=str(i.get("reason", "")), detail=str(i.get("detail", "")))
            for i in found
            if isinstance(i, Mapping)
        ]
        for name, found in _dict(data.get("issues")).items()
        if isinstance(found, list)
    }
    running = data.get("running")
    intake, memory = _dict(data.get("intake")), _dict(data.get("memory"))
    intake_state = IntakeState(
        dropped=_int(intake.get("dropped")),
        queued=_int(intake.get("queued")),
        max_samples=_int(intake.get("max_items")),
        lag_s=_int(intake.get("lag_ms")) / 1000,
        lag_alarm_s=config.intake.lag_alarm / 1e9,
        rss_bytes=_int(memory.get("rss_bytes")),
        bound_bytes=_int(memory.get("bound_bytes")),
    )
    return EdgeSnapshot(
        mappings=mappings,
        issues=issues,
        buffers=tuple(buffers),
        wan=wan,
        wan_link_up=all(healthy) if healthy else None,
        sequence_gaps=gaps,
        unmapped=unmapped,
        failure=None if running is not False else "the edge agent is not running",
        lost_before_spool={
            str(robot): {str(topic): _int(n) for topic, n in _dict(topics).items()}
            for robot, topics in _dict(data.get("lost_before_spool")).items()
        },
        spool_damage=damage,
        intake=intake_state,
    )


def robots_from_agent(data: Mapping[str, Any], robots: Mapping[str, str]) -> list[RobotStatus]:
    """Registered robots; registration times and states from ``robot_details`` when the agent
    reports them (``{robot: {"registered_at_ms", "state", "explicit"}}``)."""
    details = _dict(data.get("robot_details"))
    histories = _dict(data.get("robot_history"))
    out = []
    for robot, kind in sorted(robots.items()):
        detail = _dict(details.get(robot))
        at_ms = detail.get("registered_at_ms")
        state: RobotState = "lost" if detail.get("state") == "lost" else "registered"
        events = histories.get(robot)
        history = tuple(
            RobotEvent(
                event=str(e.get("event", "")),
                robot_type=str(e.get("robot_type", "")),
                reason=str(e.get("reason", "")),
                at=_int(e.get("at_ms")) / 1000,
            )
            for e in (events if isinstance(events, list) else [])
            if isinstance(e, Mapping)
        )
        out.append(
            RobotStatus(
                robot=robot,
                robot_type=kind,
                registered_at=at_ms / 1000 if isinstance(at_ms, int | float) else None,
                state=state,
                explicit=bool(detail.get("explicit", False)),
                history=history,
            )
        )
    return out


class AgentBackend:
    """An ``AdminBackend`` over a started ``EdgeAgent``, with a ``GraphWatcher`` of its own on the agent's
    session."""

    def __init__(self, agent: EdgeAgent) -> None:
        self.agent = agent
        self._graph: GraphWatcher | None = None

    def start(self) -> AgentBackend:
        """Start watching the ROS graph on the agent's session (once); returns ``self``."""
        if self._graph is None:
            self._graph = GraphWatcher(self.agent.session, self.agent.config.ros.domain_id).start()
        return self

    def stop(self) -> None:
        """Stop the graph watcher, if it runs; the agent itself keeps running."""
        if self._graph is not None:
            self._graph.stop()
            self._graph = None

    def __enter__(self) -> AgentBackend:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def install(
        self, config: EdgeConfig, robot_types: Sequence[RobotTypeSpec], mappings: Sequence[MappingSpec]
    ) -> None:
        """Apply ``config`` through ``EdgeAgent.reload``, which builds its own specs from it."""
        # EdgeAgent.reload builds its own specs from ``config`` (robot_types/mappings are the same
        # declarations); it swaps the table atomically and refreshes the subscriptions.
        del robot_types, mappings
        self.agent.reload(config)

    def mapping_table(self) -> MappingTable:
        """The agent's live mapping table."""
        return self.agent.table

    def topics(self) -> Mapping[str, TopicInfo]:
        """The discovered ROS topics; empty until ``start`` has run."""
        return {} if self._graph is None else self._graph.topics()

    def robots(self) -> Sequence[RobotStatus]:
        """Each robot the agent knows, with its state and registration history."""
        return robots_from_agent(self.agent.snapshot(), self.agent.robots())

    def snapshot(self) -> EdgeSnapshot:
        """The agent's counters and state now, as an ``EdgeSnapshot``."""
        return snapshot_from_agent(self.agent.snapshot(), self.agent.config)

    def spool_damage(self) -> Sequence[Mapping[str, Any]]:
        """Every damage finding of the agent's durable spool, acknowledged or not."""
        return self.agent.spool_damage()

    def acknowledge_spool_damage(self) -> Sequence[Mapping[str, Any]]:
        """Acknowledge the agent's spool damage findings; returns those that were waiting."""
        return self.agent.acknowledge_spool_damage()
