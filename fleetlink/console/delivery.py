"""What Kafka acknowledged, added up over every uplink (pure: ``now`` is passed in).

Each uplink answers its own running totals per site on ``fleetlink/<site>/delivery/<uplink>``
(``uplink.delivery_status``); uplinks keep no state and several may serve a fleet, so no one
of them knows the whole. ``delivery_view`` adds the answers up: batches by status, records
in Kafka, dead letters, records Kafka acknowledged per topic and their rate (each uplink's
counter measured on its own, then summed, so an uplink that restarts does not make the
fleet's rate jump), and the Kafka delivery latency of the last minute from every uplink's
samples.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

from fleetlink.console.rates import RateBoard


def _int(value: Any) -> int:
    return int(value) if isinstance(value, int | float) and not isinstance(value, bool) else 0


def _dict(value: Any) -> Mapping[str, Any]:
    return value if isinstance(value, Mapping) else {}


def _sum(values: Iterable[float | None]) -> float | None:
    known = [v for v in values if v is not None]
    return sum(known) if known else None


def percentile(values: list[float], q: float) -> float:
    """The ``q`` quantile (0..1) of sorted ``values`` by the nearest-rank rule."""
    rank = max(1, min(len(values), math.ceil(q * len(values))))
    return values[rank - 1]


def merged_latency(answers: Iterable[Mapping[str, Any]]) -> dict[str, Any] | None:
    """One latency summary from several uplinks' ``latency`` parts (``None``: no batch in the window)."""
    batches, samples, maxima, window = 0, [], [], 60.0
    for answer in answers:
        part = _dict(answer.get("latency"))
        batches += _int(part.get("batches"))
        samples += [float(v) for v in part.get("samples_ms") or () if isinstance(v, int | float)]
        if isinstance(part.get("max_ms"), int | float):
            maxima.append(float(part["max_ms"]))
        if isinstance(part.get("window_s"), int | float):
            window = float(part["window_s"])
    if not batches or not samples:
        return None
    samples.sort()
    return {
        "batches": batches,
        "p50_ms": round(percentile(samples, 0.5), 1),
        "p95_ms": round(percentile(samples, 0.95), 1),
        "max_ms": round(max(maxima or samples), 1),
        "window_s": window,
    }


def delivery_view(board: RateBoard, answers: Iterable[Mapping[str, Any]], *, now: float) -> dict[str, Any]:
    """The uplinks' answers (for one site or several) -> totals, per-topic rates, latency."""
    answers = [a for a in answers if isinstance(a.get("uplink"), str) and isinstance(a.get("site"), str)]
    batches: dict[str, int] = {}
    topics: dict[str, dict[str, Any]] = {}
    topic_rates: dict[str, list[float | None]] = {}
    uplinks = []
    records = dead = 0
    for answer in answers:
        uplink, site = str(answer["uplink"]), str(answer["site"])
        for status, n in _dict(answer.get("batches")).items():
            batches[str(status)] = batches.get(str(status), 0) + _int(n)
        records += _int(answer.get("records"))
        dead += _int(answer.get("dead_lettered"))
        for topic, n in _dict(answer.get("topics")).items():
            entry = topics.setdefault(str(topic), {"acked": 0, "rate": None})
            entry["acked"] += _int(n)
            rate = board.rate((site, "kafka", uplink, str(topic)), float(_int(n)), now)
            topic_rates.setdefault(str(topic), []).append(rate)
        uplinks.append(
            {
                "uplink": uplink,
                "site": site,
                "batches": {str(k): _int(v) for k, v in _dict(answer.get("batches")).items()},
                "records": _int(answer.get("records")),
                "dead_lettered": _int(answer.get("dead_lettered")),
                "started_at": answer.get("started_at"),
            }
        )
    for topic, rates in topic_rates.items():
        topics[topic]["rate"] = _sum(rates)
    return {
        "uplinks": sorted(uplinks, key=lambda u: (u["site"], u["uplink"])),
        "uplink_count": len({u["uplink"] for u in uplinks}),
        "batches": batches,
        "records": records,
        "dead_lettered": dead,
        "topics": dict(sorted(topics.items())),
        "rate": _sum(t["rate"] for t in topics.values()),
        "latency": merged_latency(answers),
    }
