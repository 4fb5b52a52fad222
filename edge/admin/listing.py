"""Read-only views of the running edge: mappings with counters, robots, topics, dry runs (pure)."""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterable, Mapping, Sequence

from fleetlink.edge.admin.backend import EdgeSnapshot, MappingCounts, RobotStatus
from fleetlink.edge.admin.overlay import Overlay
from fleetlink.edge.admin.views import (
    DryRunMatchView,
    DryRunView,
    IssueView,
    MappingCountersView,
    MappingView,
    PublisherView,
    RobotEventView,
    RobotView,
    StageView,
    TopicMatchView,
    TopicView,
)
from fleetlink.edge.config import EdgeConfig, MappingConfig
from fleetlink.edge.errors import MappingError
from fleetlink.edge.mapping import BoundMapping, MappingTable, RobotTypeSpec
from fleetlink.edge.stages import StageConfigError, StageSpec, build_pipeline
from fleetlink.roswire.graph import TopicInfo

_STAGE_KEYS = ("received", "passed", "dropped", "late", "errors", "emitted")


def stage_names(stages: Sequence[StageSpec]) -> list[str]:
    """The names the runtime gives the stages (``throttle``, ``throttle_2`` ...)."""
    try:
        return [stage.name for stage in build_pipeline(list(stages)).stages]
    except StageConfigError:
        return [spec.name or spec.type for spec in stages]


def declared(config: EdgeConfig) -> list[tuple[MappingConfig, str | None]]:
    """Every mapping of ``config`` with its robot type (site-level first)."""
    out: list[tuple[MappingConfig, str | None]] = [(m, None) for m in config.mappings]
    out += [(m, name) for name, rt in config.robot_types.items() for m in rt.mappings]
    return out


def mapping_views(
    config: EdgeConfig, overlay: Overlay, table: MappingTable, snapshot: EdgeSnapshot
) -> list[MappingView]:
    """Each declared mapping with its origin, robots, counters, stage counters and issues."""
    robots = {info.name: list(info.robots) for info in table.list()}
    views = []
    for mapping, owner in declared(config):
        counts = snapshot.mappings.get(mapping.name, MappingCounts())
        stages = []
        for spec, name in zip(mapping.stages, stage_names(mapping.stages), strict=True):
            values = counts.stages.get(name, {})
            numbers = {k: int(values.get(k, 0)) for k in _STAGE_KEYS}
            stages.append(StageView(name=name, type=spec.type, **numbers))
        issues = [IssueView(reason=i.reason, detail=i.detail) for i in snapshot.issues.get(mapping.name, ())]
        counters = MappingCountersView(
            received=counts.received,
            emitted=counts.emitted,
            dropped=counts.dropped,
            dead_lettered=counts.dead_lettered,
            type_mismatch=counts.type_mismatch,
        )
        views.append(
            MappingView.model_validate(
                {
                    "name": mapping.name,
                    "robot_type": owner,
                    "origin": "admin" if overlay.mapping(mapping.name) is not None else "config",
                    "from": mapping.from_,
                    "to": mapping.to,
                    "key": mapping.key,
                    "type": mapping.type,
                    "delivery": mapping.delivery,
                    "stages": [s.model_dump(mode="json", exclude_none=True) for s in mapping.stages],
                    "robots": robots.get(mapping.name, []),
                    "counters": counters,
                    "stage_counters": stages,
                    "issues": issues,
                }
            )
        )
    return views


def robot_views(robots: Iterable[RobotStatus]) -> list[RobotView]:
    """The robots sorted by name, each with its registration time as ISO 8601 UTC text."""
    out = []
    for robot in sorted(robots, key=lambda r: r.robot):
        since = None
        if robot.registered_at is not None:
            when = dt.datetime.fromtimestamp(robot.registered_at, tz=dt.UTC)
            since = when.isoformat(timespec="milliseconds")
        out.append(
            RobotView(
                robot=robot.robot,
                robot_type=robot.robot_type,
                registered_at=robot.registered_at,
                registered_since=since,
                state=robot.state,
                explicit=robot.explicit,
                history=[
                    RobotEventView(
                        event="registered" if e.event == "registered" else "deregistered",
                        robot_type=e.robot_type,
                        reason=e.reason,
                        at=e.at,
                    )
                    for e in robot.history
                ],
            )
        )
    return out


def _match_view(bound: BoundMapping) -> TopicMatchView:
    return TopicMatchView(
        mapping=bound.name,
        robot=bound.robot,
        kafka_topic=bound.kafka_topic or bound.topic_template.text,
        key=bound.key if bound.key is not None else bound.key_template.text,
    )


def topic_views(topics: Mapping[str, TopicInfo], table: MappingTable) -> list[TopicView]:
    """The discovered topics sorted by name, each with its publishers and the mappings that match it."""
    out = []
    for name in sorted(topics):
        info = topics[name]
        publishers = [
            PublisherView(node=p.node_fqn, type=p.ros_type, type_hash=p.type_hash) for p in info.publishers
        ]
        out.append(
            TopicView(
                topic=name,
                types=list(info.types),
                publishers=publishers,
                subscribers=len(info.subscribers),
                mappings=[_match_view(b) for b in table.match(name)],
            )
        )
    return out


def dry_run_matches(
    config: EdgeConfig, name: str, topics: Mapping[str, TopicInfo], live: MappingTable
) -> DryRunView:
    """The topics of the graph that the mapping ``name`` of ``config`` matches, with the robots the
    live edge has registered, plus robots seen in the graph that its robot type would take."""
    mapping, owner = next((m, o) for m, o in declared(config) if m.name == name)
    spec = mapping.spec()
    registered: set[str] = set()
    if owner is None:
        table = MappingTable([], [spec])
    else:
        robot_type = RobotTypeSpec(name=owner, match=config.robot_types[owner].match, mappings=(spec,))
        table = MappingTable([robot_type])
        registered = {robot for robot, kind in live.robots().items() if kind == owner}
        seen = {topic.strip("/").split("/")[0] for topic in topics}
        for robot in sorted(registered | {r for r in seen if r and table.robot_type_for(r) == owner}):
            try:
                table.add_robot(robot, owner)
            except MappingError:
                continue
    matches = []
    for topic in sorted(topics):
        info = topics[topic]
        for bound in table.match(topic):
            view = _match_view(bound)
            matches.append(
                DryRunMatchView(
                    topic=topic,
                    types=list(info.types),
                    robot=bound.robot,
                    registered=owner is None or bound.robot in registered,
                    kafka_topic=view.kafka_topic,
                    key=view.key,
                    type_ok=spec.ros_type is None or spec.ros_type in info.types,
                )
            )
    return DryRunView(mapping=name, robot_type=owner, matches=matches)
