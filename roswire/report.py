"""What ``fleetlink ros graph`` prints: a plain-data report of robots, nodes, topics and services,
rendered as text or JSON. Pure functions over graph snapshots."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping
from typing import Any

from fleetlink.roswire.errors import KeyParseError
from fleetlink.roswire.graph import TopicInfo
from fleetlink.roswire.names import parse_data_key
from fleetlink.roswire.qos import describe
from fleetlink.roswire.robots import Robot
from fleetlink.roswire.tokens import EndpointInfo, NodeInfo


class RateMeter:
    """Counts samples per topic from data keys; :meth:`rates` divides by the elapsed time."""

    def __init__(self) -> None:
        self.counts: Counter[str] = Counter()
        self.unparsed = 0

    def on_key(self, key: str) -> None:
        """Count one sample on the topic of data key ``key`` (a key that does not parse is counted apart)."""
        try:
            self.counts[parse_data_key(key).topic] += 1
        except KeyParseError:
            self.unparsed += 1

    def rates(self, elapsed_s: float) -> dict[str, float]:
        """Topic -> samples per second over ``elapsed_s`` seconds (empty when no time has passed)."""
        if elapsed_s <= 0:
            return {}
        return {topic: count / elapsed_s for topic, count in self.counts.items()}

    def reset(self) -> None:
        """Start counting afresh (the unparsed count is kept)."""
        self.counts.clear()


def _endpoint(ep: EndpointInfo) -> dict[str, Any]:
    return {
        "node": ep.node_fqn,
        "zid": ep.zid,
        "type": ep.ros_type,
        "type_hash": ep.type_hash,
        "qos": describe(ep.qos),
        "qos_wire": ep.qos.to_keyexpr(),
        "gid": ep.gid.hex(),
    }


def _topic(info: TopicInfo, rate: float | None, first: str, second: str) -> dict[str, Any]:
    entry: dict[str, Any] = {
        "name": info.name,
        "types": list(info.types),
        first: [_endpoint(e) for e in info.publishers],
        second: [_endpoint(e) for e in info.subscribers],
    }
    if rate is not None:
        entry["rate_hz"] = round(rate, 2)
    return entry


def graph_report(
    *,
    domain_id: int,
    robots: Iterable[Robot],
    nodes: Iterable[NodeInfo],
    topics: Mapping[str, TopicInfo],
    services: Mapping[str, TopicInfo],
    rates: Mapping[str, float] | None = None,
    malformed_tokens: int = 0,
) -> dict[str, Any]:
    """The report as plain data (JSON-ready): robots, nodes, topics with endpoints and rates, services."""
    return {
        "domain_id": domain_id,
        "robots": [
            {"name": r.name, "type": r.robot_type, "entities": len(r.entities), "explicit": r.explicit}
            for r in robots
        ],
        "nodes": [
            {
                "name": n.name,
                "namespace": n.namespace,
                "fqn": n.fqn,
                "zid": n.zid,
                "nid": n.nid,
                "enclave": n.enclave,
            }
            for n in nodes
        ],
        "topics": [
            _topic(t, None if rates is None else rates.get(name, 0.0), "publishers", "subscribers")
            for name, t in topics.items()
        ],
        "services": [_topic(s, None, "servers", "clients") for s in services.values()],
        "malformed_tokens": malformed_tokens,
    }


def render_text(report: Mapping[str, Any]) -> str:
    """The report from :func:`graph_report` as lines of text for a terminal."""
    lines = [f"domain {report['domain_id']}"]
    lines.append(f"robots ({len(report['robots'])}):")
    lines += [
        f"  {r['name']:<16} type={r['type']} entities={r['entities']}"
        + (" (registered)" if r["explicit"] else "")
        for r in report["robots"]
    ]
    lines.append(f"nodes ({len(report['nodes'])}):")
    lines += [f"  {n['fqn']:<32} zid={n['zid']}" for n in report["nodes"]]
    lines.append(f"topics ({len(report['topics'])}):")
    for t in report["topics"]:
        qos = sorted({e["qos"] for e in t["publishers"]})
        rate = f" {t['rate_hz']:.1f} Hz" if "rate_hz" in t else ""
        lines.append(
            f"  {t['name']:<32} {', '.join(t['types'])}  pub={len(t['publishers'])} "
            f"sub={len(t['subscribers'])}{rate}" + "".join(f"  [{q}]" for q in qos)
        )
    lines.append(f"services ({len(report['services'])}):")
    lines += [
        f"  {s['name']:<32} {', '.join(s['types'])}  servers={len(s['servers'])} clients={len(s['clients'])}"
        for s in report["services"]
    ]
    if report.get("malformed_tokens"):
        lines.append(f"malformed liveliness tokens ignored: {report['malformed_tokens']}")
    return "\n".join(lines)
