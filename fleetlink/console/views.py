"""What a console page polls: one site's view, assembled from the admin answers (pure apart
from the ``RateBoard``'s memory; ``now`` is passed in).

``site_view`` takes the envelopes of one read (``robots``, ``topics``, ``mappings``,
``robot_types``, ``health``, ``status``), turns counters into rates, builds the graph, and says
which parts could not be read (``errors``), so a page shows what it has and names what it lacks.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from fleetlink.console.delivery import delivery_view
from fleetlink.console.envelope import Envelope
from fleetlink.console.graph import build_graph
from fleetlink.console.rates import RateBoard

PARTS = ("robots", "topics", "mappings", "robot_types", "health", "status")
MAPPING_RATES = ("received", "emitted", "filtered", "dropped", "dead_lettered")


def _body(parts: Mapping[str, Envelope], name: str, errors: dict[str, str]) -> Any:
    env = parts.get(name)
    if env is None:
        errors[name] = "not reported by this site"
        return None
    if env.ok or env.body is not None:  # a failed site's health: status 503 with its report
        return env.body
    errors[name] = f"{env.status}: {env.error or 'refused'}"
    return None


def _list(value: Any) -> list[dict[str, Any]]:
    return [v for v in value if isinstance(v, dict)] if isinstance(value, list) else []


def intended_drops(mapping: Mapping[str, Any]) -> int:
    """Samples the mapping's stages left out by their rule (a throttle, a filter, a dedupe, a
    watermark): what the mapping was told to do, not a problem."""
    stages = mapping.get("stage_counters")
    if not isinstance(stages, list):
        return 0
    return sum(
        int(s.get("dropped", 0) or 0) + int(s.get("late", 0) or 0) for s in stages if isinstance(s, dict)
    )


def mapping_rates(
    board: RateBoard, site: str, mappings: list[dict[str, Any]], now: float
) -> dict[str, dict[str, float | None]]:
    """Per mapping: received, emitted, ``filtered`` (left out by its stages on purpose),
    ``dropped`` (lost otherwise: a stage error, another ROS type than declared) and
    dead-lettered records per second."""
    out = {}
    for mapping in mappings:
        counters = mapping.get("counters") or {}
        name = str(mapping.get("name"))
        filtered = intended_drops(mapping)
        lost = counters.get("dropped", 0) + counters.get("type_mismatch", 0)
        values = {
            "received": counters.get("received", 0),
            "emitted": counters.get("emitted", 0),
            "filtered": filtered,
            "dropped": max(0, lost - filtered),
            "dead_lettered": counters.get("dead_lettered", 0),
        }
        out[name] = {k: board.rate((site, "mapping", name, k), float(v), now) for k, v in values.items()}
    return out


def topic_rates(board: RateBoard, site: str, status: Any, now: float) -> dict[str, float | None]:
    """Samples received per second on each ROS topic of the edge's ``status`` counters."""
    topics = status.get("topics") if isinstance(status, dict) else None
    if not isinstance(topics, dict):
        return {}
    return {
        str(topic): board.rate((site, "topic", str(topic)), float(counts.get("received", 0)), now)
        for topic, counts in topics.items()
        if isinstance(counts, dict)
    }


def backlog(status: Any) -> dict[str, Any] | None:
    """What waits in the edge's buffers for Kafka: records, bytes, the oldest record's age."""
    streams = status.get("streams") if isinstance(status, dict) else None
    if not isinstance(streams, list):
        return None
    found = [s for s in streams if isinstance(s, dict)]
    return {
        "records": sum(int(s.get("depth", 0) or 0) for s in found),
        "bytes": sum(int(s.get("bytes", 0) or 0) for s in found),
        "oldest_age_s": max((float(s.get("oldest_age_s", 0) or 0) for s in found), default=0.0),
    }


def _rate(
    board: RateBoard,
    site: str,
    mappings: list[dict[str, Any]],
    delivery: list[dict[str, Any]] | None,
    now: float,
) -> tuple[dict[str, dict[str, float | None]], dict[str, Any]]:
    """Each mapping's rates (also set as its ``rates``) and the uplinks' delivery view."""
    rates = mapping_rates(board, site, mappings, now)
    for mapping in mappings:
        mapping["rates"] = rates.get(str(mapping.get("name")), {})
    return rates, delivery_view(board, delivery or [], now=now)


def site_figures(
    site: str,
    parts: Mapping[str, Envelope],
    board: RateBoard,
    *,
    now: float,
    delivery: list[dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """What the history keeps of a site, from its ``mappings`` and ``status`` alone: the mappings
    with their rates, the backlog (as ``graph.backlog``) and what the uplinks delivered. The part
    of ``site_view`` that does not grow with the fleet (no robots, topics or graph)."""
    errors: dict[str, str] = {}
    mappings = _list(_body(parts, "mappings", errors))
    _rates, kafka = _rate(board, site, mappings, delivery, now)
    board.forget_idle(now)
    return {
        "site": site,
        "mappings": mappings,
        "graph": {"backlog": backlog(_body(parts, "status", errors))},
        "delivery": kafka if delivery is not None else None,
    }


def site_view(
    site: str,
    parts: Mapping[str, Envelope],
    board: RateBoard,
    *,
    now: float,
    delivery: list[dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """``delivery``: every uplink's delivery figures for the site (``None``: this process cannot
    ask them); the Kafka column shows what they acknowledged."""
    errors: dict[str, str] = {}
    robots = _list(_body(parts, "robots", errors))
    topics = _list(_body(parts, "topics", errors))
    mappings = _list(_body(parts, "mappings", errors))
    robot_types_body = _list(_body(parts, "robot_types", errors))
    robot_types = [str(t["name"]) for t in robot_types_body if "name" in t]
    health = _body(parts, "health", errors)
    status = _body(parts, "status", errors)
    per_topic = topic_rates(board, site, status, now)
    rates, kafka = _rate(board, site, mappings, delivery, now)
    board.forget_idle(now)
    edge_ids = sorted({e.edge_id for e in parts.values() if e.edge_id})
    kafka_rates = None
    if delivery is not None:
        kafka_rates = {topic: entry["rate"] for topic, entry in kafka["topics"].items()}
    return {
        "site": site,
        "edge_id": ", ".join(edge_ids),
        "at": now,
        "errors": errors,
        "health": health if isinstance(health, dict) else None,
        "status": status if isinstance(status, dict) else None,
        "robots": robots,
        "robot_types": robot_types,
        "robot_type_details": robot_types_body,
        "mappings": mappings,
        "topic_rates": per_topic,
        "delivery": kafka if delivery is not None else None,
        "latency": kafka["latency"],
        "graph": build_graph(
            robots,
            topics,
            mappings,
            topic_rates=per_topic,
            mapping_rates=rates,
            kafka_rates=kafka_rates,
            backlog=backlog(status),
        ),
    }


def site_summary(site: str, health: Envelope) -> dict[str, Any]:
    """One line of the fleet page from a site's health answer."""
    body = health.body if isinstance(health.body, dict) else {}
    return {
        "site": site,
        "edge_id": health.edge_id,
        "status": health.status,
        "state": body.get("state"),
        "robots": body.get("robots"),
        "wan_link_up": body.get("wan_link_up"),
        "problems": len(body.get("problems", ())) if isinstance(body.get("problems"), list) else None,
        "error": None if health.body is not None else (health.error or f"status {health.status}"),
    }


def robot_view(
    site: str, robot: str, parts: Mapping[str, Envelope], latest: Envelope | None
) -> dict[str, Any]:
    """A robot's page: its registration (and history), the topics it publishes with the mappings
    each feeds, and the latest value of each mapped topic (when the edge answered them)."""
    errors: dict[str, str] = {}
    robots = _list(_body(parts, "robots", errors))
    topics = _list(_body(parts, "topics", errors))
    found = next((r for r in robots if r.get("robot") == robot), None)
    own = []
    for topic in topics:
        name = str(topic.get("topic", ""))
        feeds = [m for m in topic.get("mappings", ()) if isinstance(m, dict) and m.get("robot") == robot]
        if feeds or name.startswith(f"/{robot}/"):
            own.append(
                {"topic": name, "types": topic.get("types", []), "mappings": feeds, "mapped": bool(feeds)}
            )
    values: dict[str, Any] = {}
    if latest is None:
        errors["latest"] = "not available on this process"
    elif latest.ok and isinstance(latest.body, dict):
        values = latest.body
    else:
        errors["latest"] = f"{latest.status}: {latest.error or 'refused'}"
    return {
        "site": site,
        "robot": robot,
        "registered": found is not None,
        "registration": found,
        "history": (found or {}).get("history", []),
        "topics": sorted(own, key=lambda t: (not t["mapped"], t["topic"])),
        "latest": values,
        "errors": errors,
    }
