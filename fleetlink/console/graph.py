"""The live graph of one site: robots -> ROS topics -> mappings -> Kafka topics (pure).

Inputs are the admin API's JSON views (robots, topics with the mappings each feeds, mappings
with counters) and the rates the caller computed from counter deltas; the output is four
columns of nodes and the edges between them, each with a rate where one is known
(records per second; ``None``: not known yet).

A site's graph shows that site alone, whatever the router topology: robots registered at this
edge and the topics they publish, and any topic one of its mappings takes. Namespaces seen on
the ROS graph that no mapping takes and no robot type registered here (another site's robots,
when routers are linked; a robot of no known type) are only counted (``elsewhere``), and
fleetlink's own topics (``/fleetlink/...``: registration, robot events) are never a robot.

The Kafka column says what Kafka *acknowledged* for this site's records (``kafka_rates``, from
every uplink's delivery figures); the mappings' output is shown beside it (``mapped``). A
mapping's line to a Kafka topic carries its share of the acknowledged rate, so during a WAN
outage the lines go idle while the mappings keep producing into the spool (``backlog``).
A mapping that feeds several Kafka topics (a template such as ``fleet.{robot}.imu``) has its
output rate split evenly between them, and those Kafka nodes say their rate is approximate.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

SITE_LEVEL = "(site)"
OWN_NAMESPACE = "fleetlink"
"""fleetlink's own ROS topics live under ``/fleetlink/`` (register topic, robot events)."""


def is_own(topic: str) -> bool:
    """Whether ``topic`` is one of fleetlink's own (``/fleetlink`` or below it)."""
    return topic == f"/{OWN_NAMESPACE}" or topic.startswith(f"/{OWN_NAMESPACE}/")


def _robot_of(topic: Mapping[str, Any], registered: Sequence[str]) -> tuple[str, str]:
    """(robot, state) for a topic: the robot its mappings name (the site itself when they name
    none), a registered robot whose namespace holds it, the first namespace segment (a robot not
    registered), or the site."""
    matches = list(topic.get("mappings", ()))
    for match in matches:
        if match.get("robot"):
            robot = str(match["robot"])
            return robot, "registered" if robot in registered else "unregistered"
    if matches:  # mapped by site-level mappings that capture no robot
        return SITE_LEVEL, "site"
    name = str(topic.get("topic", ""))
    owners = [r for r in registered if name.startswith(f"/{r}/")]
    if owners:
        return max(owners, key=len), "registered"
    parts = name.strip("/").split("/")
    if len(parts) > 1 and parts[0]:
        return parts[0], "unregistered"
    return SITE_LEVEL, "site"


def _add(nodes: dict[str, dict[str, Any]], node: dict[str, Any]) -> None:
    nodes.setdefault(node["id"], node)


def _sum(values: Sequence[float | None]) -> float | None:
    known = [v for v in values if v is not None]
    return sum(known) if known else None


def build_graph(
    robots: Sequence[Mapping[str, Any]],
    topics: Sequence[Mapping[str, Any]],
    mappings: Sequence[Mapping[str, Any]],
    *,
    topic_rates: Mapping[str, float | None],
    mapping_rates: Mapping[str, Mapping[str, float | None]],
    kafka_rates: Mapping[str, float | None] | None = None,
    backlog: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """``kafka_rates``: records/s Kafka acknowledged per topic for this site (``None``: no uplink
    reported; a topic missing from it had none); ``backlog``: what waits in the spool."""
    states = {str(r["robot"]): str(r.get("state", "registered")) for r in robots}
    kinds = {str(r["robot"]): str(r.get("robot_type", "")) for r in robots}
    robot_nodes: dict[str, dict[str, Any]] = {}
    for name in sorted(states):
        _add(
            robot_nodes,
            {
                "id": f"r:{name}",
                "label": name,
                "state": states[name],
                "detail": f"{kinds[name]} · {states[name]}",
            },
        )
    topic_nodes: dict[str, dict[str, Any]] = {}
    edges: list[dict[str, Any]] = []
    targets: dict[str, set[str]] = {str(m["name"]): set() for m in mappings}
    fed: dict[str, list[str]] = {}
    elsewhere: dict[str, int] = {}
    for topic in topics:
        name = str(topic["topic"])
        matches = list(topic.get("mappings", ()))
        if is_own(name) or (not topic.get("publishers") and not matches):
            continue
        robot, state = _robot_of(topic, sorted(states))
        if state == "unregistered" and not matches:
            elsewhere[robot] = elsewhere.get(robot, 0) + 1
            continue
        if f"r:{robot}" not in robot_nodes:
            detail = "not registered here" if state == "unregistered" else "topics outside any robot"
            _add(robot_nodes, {"id": f"r:{robot}", "label": robot, "state": state, "detail": detail})
        rate = topic_rates.get(name)
        types = ", ".join(str(t) for t in topic.get("types", ()))
        _add(
            topic_nodes,
            {
                "id": f"t:{name}",
                "label": name,
                "detail": types,
                "rate": rate,
                "mapped": bool(matches),
                "robot": f"r:{robot}",
            },
        )
        edges.append({"from": f"r:{robot}", "to": f"t:{name}", "rate": rate})
        for match in matches:
            mapping = str(match["mapping"])
            edges.append({"from": f"t:{name}", "to": f"m:{mapping}", "rate": rate})
            targets.setdefault(mapping, set()).add(str(match["kafka_topic"]))
            fed.setdefault(mapping, []).append(name)
    mapping_nodes, kafka_nodes = _mapping_columns(
        mappings, mapping_rates, targets, fed, edges, kafka_rates=kafka_rates
    )
    order = {node_id: i for i, node_id in enumerate(robot_nodes)}
    ordered = sorted(topic_nodes.values(), key=lambda n: (order[n["robot"]], n["label"]))
    return {
        "robots": list(robot_nodes.values()),
        "topics": ordered,
        "mappings": mapping_nodes,
        "kafka": kafka_nodes,
        "edges": edges,
        "elsewhere": dict(sorted(elsewhere.items())),
        "backlog": dict(backlog) if backlog is not None else None,
        "kafka_reported": kafka_rates is not None,
    }


def _mapping_columns(
    mappings: Sequence[Mapping[str, Any]],
    mapping_rates: Mapping[str, Mapping[str, float | None]],
    targets: Mapping[str, set[str]],
    fed: Mapping[str, list[str]],
    edges: list[dict[str, Any]],
    *,
    kafka_rates: Mapping[str, float | None] | None,
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The mapping and Kafka columns; appends the mapping -> Kafka edges to ``edges``."""
    nodes = []
    shares: dict[str, list[tuple[str, float | None]]] = {}
    approx: set[str] = set()
    for entry in mappings:
        name = str(entry["name"])
        rates = mapping_rates.get(name, {})
        owner = entry.get("robot_type")
        nodes.append(
            {
                "id": f"m:{name}",
                "label": name,
                "detail": f"{owner} template" if owner else "site mapping",
                "in": rates.get("received"),
                "out": rates.get("emitted"),
                "drop": rates.get("dropped"),
                "filtered": rates.get("filtered"),
                "dead": rates.get("dead_lettered"),
                "degraded": bool(entry.get("issues")),
                "topics": len(fed.get(name, ())),
            }
        )
        kafka = targets.get(name) or {str(entry.get("to", ""))}
        out = rates.get("emitted")
        for kafka_topic in sorted(kafka):
            share = None if out is None else out / len(kafka)
            shares.setdefault(kafka_topic, []).append((name, share))
            if len(kafka) > 1:
                approx.add(kafka_topic)
    kafka_nodes = []
    for topic, parts in sorted(shares.items()):
        mapped = _sum([share for _, share in parts])
        acked = None if kafka_rates is None else kafka_rates.get(topic, 0.0)
        for name, share in parts:
            rate = _portion(acked, share, mapped, parts)
            edges.append({"from": f"m:{name}", "to": f"k:{topic}", "rate": rate})
        kafka_nodes.append(
            {"id": f"k:{topic}", "label": topic, "rate": acked, "mapped": mapped, "approx": topic in approx}
        )
    return nodes, kafka_nodes


def _portion(
    acked: float | None,
    share: float | None,
    mapped: float | None,
    parts: Sequence[tuple[str, float | None]],
) -> float | None:
    """A mapping's part of what Kafka acknowledged for a topic: in proportion to what it mapped
    (evenly while nothing is mapped, e.g. while a backlog drains)."""
    if acked is None:
        return None
    if share is not None and mapped:
        return acked * share / mapped
    return acked / len(parts)
