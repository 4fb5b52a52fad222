"""An edge's state for the console's health panel and graph (pure: ``now_ms`` is passed in).

From the admin backend's ``EdgeSnapshot``: each buffer's depth, bytes, fill and the age of its
oldest unacknowledged record; each WAN stream's totals; the link state. From the agent's own
snapshot when there is one: per-ROS-topic sample counters (the graph's topic rates) and each
sender's outage time and last error. Served on ``/console/api`` locally and on
``fleetlink/<site>/console/status`` for the fleet console.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from fleetlink.edge.admin.backend import EdgeSnapshot

_TOPIC_KEYS = ("received", "delivered", "rejected", "gaps", "missing", "duplicates")


def _int(value: Any) -> int:
    return int(value) if isinstance(value, int | float) and not isinstance(value, bool) else 0


def _dict(value: Any) -> Mapping[str, Any]:
    return value if isinstance(value, Mapping) else {}


def site_status(snapshot: EdgeSnapshot, raw: Mapping[str, Any] | None, *, now_ms: int) -> dict[str, Any]:
    """The edge's counters for the console: each buffer's depth, fill and oldest age, each WAN stream's
    totals and sender health, and each ROS topic's sample counters (from ``raw``)."""
    raw_streams = _dict((raw or {}).get("streams"))
    streams = []
    for buffer in snapshot.buffers:
        stats = buffer.stats
        fill = stats.bytes / buffer.capacity_bytes if buffer.capacity_bytes > 0 else None
        streams.append(
            {
                "stream": stats.stream,
                "depth": stats.depth,
                "bytes": stats.bytes,
                "capacity_bytes": buffer.capacity_bytes,
                "fill": None if fill is None else round(fill, 4),
                "oldest_age_s": round(stats.oldest_age_ms(now_ms) / 1000, 3),
                "in_flight": stats.in_flight,
                "appended": stats.appended,
                "acked": stats.acked,
                "dropped": stats.dropped_oldest + stats.dropped_newest,
                "blocked_appenders": stats.blocked_appenders,
            }
        )
    wan = {}
    for stream, totals in sorted(snapshot.wan.items()):
        sender = _dict(_dict(raw_streams.get(stream)).get("sender"))
        wan[stream] = {
            "batches_sent": totals.batches_sent,
            "batches_acked": totals.batches_acked,
            "records_acked": totals.records_acked,
            "batches_retried": totals.batches_retried,
            "in_flight": totals.in_flight,
            "healthy": sender.get("healthy"),
            "outage_s": sender.get("outage_s"),
            "last_error": sender.get("last_error"),
        }
    topics = {
        str(topic): {k: _int(_dict(counts).get(k)) for k in _TOPIC_KEYS}
        for topic, counts in sorted(_dict((raw or {}).get("subscriptions")).items())
    }
    return {
        "wan_link_up": snapshot.wan_link_up,
        "streams": streams,
        "wan": wan,
        "topics": topics,
        "sequence_gaps": dict(snapshot.sequence_gaps),
        "failure": snapshot.failure,
    }
