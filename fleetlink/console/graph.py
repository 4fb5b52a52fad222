"""The live graph of one site: robots -> ROS topics -> mappings -> Kafka topics (pure).

Inputs are the admin API's JSON views (robots, topics with the mappings each feeds, mappings
with counters) and the rates the caller computed from counter deltas; the output is four
columns of nodes and the edges between them, each with a rate where one is known
(records per second; ``None``: not known yet). A mapping that feeds several Kafka topics (a
template such as ``fleet.{robot}.imu``) has its output rate split evenly between them, and
those Kafka nodes say their rate is approximate.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

SITE_LEVEL = "(site)"


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
) -> dict[str, Any]:
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
    for topic in topics:
        name = str(topic["topic"])
        matches = list(topic.get("mappings", ()))
        if not topic.get("publishers") and not matches:
            continue
        robot, state = _robot_of(topic, sorted(states))
        if f"r:{robot}" not in robot_nodes:
            detail = "not registered" if state == "unregistered" else "topics outside any robot"
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
    mapping_nodes, kafka_nodes = _mapping_columns(mappings, mapping_rates, targets, fed, edges)
    order = {node_id: i for i, node_id in enumerate(robot_nodes)}
    ordered = sorted(topic_nodes.values(), key=lambda n: (order[n["robot"]], n["label"]))
    return {
        "robots": list(robot_nodes.values()),
        "topics": ordered,
        "mappings": mapping_nodes,
        "kafka": kafka_nodes,
        "edges": edges,
    }


def _mapping_columns(
    mappings: Sequence[Mapping[str, Any]],
    mapping_rates: Mapping[str, Mapping[str, float | None]],
    targets: Mapping[str, set[str]],
    fed: Mapping[str, list[str]],
    edges: list[dict[str, Any]],
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The mapping and Kafka columns; appends the mapping -> Kafka edges to ``edges``."""
    nodes = []
    shares: dict[str, list[float | None]] = {}
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
                "dead": rates.get("dead_lettered"),
                "degraded": bool(entry.get("issues")),
                "topics": len(fed.get(name, ())),
            }
        )
        kafka = targets.get(name) or {str(entry.get("to", ""))}
        out = rates.get("emitted")
        for kafka_topic in sorted(kafka):
            share = None if out is None else out / len(kafka)
            shares.setdefault(kafka_topic, []).append(share)
            if len(kafka) > 1:
                approx.add(kafka_topic)
            edges.append({"from": f"m:{name}", "to": f"k:{kafka_topic}", "rate": share})
    kafka_nodes = [
        {"id": f"k:{t}", "label": t, "rate": _sum(v), "approx": t in approx}
        for t, v in sorted(shares.items())
    ]
    return nodes, kafka_nodes
