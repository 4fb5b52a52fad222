"""What this uplink delivered to Kafka, per site (pure; thread-safe).

``DeliveryBoard.on_batch(site, status, topics, dead_lettered)`` is called once per answered batch
(``topics``: records Kafka acknowledged per Kafka topic, for a batch answered ``ok``).
``figures(site)`` is the site's running totals as plain data: batches by status, records in
Kafka per topic, dead letters. The uplink answers them on ``fleetlink/<site>/delivery/<id>``
(``uplink.delivery_status``), and every console adds up the answers of every uplink: uplinks
keep no state, several serve one fleet, and each sees only the batches it handled.
"""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from fleetlink._native import ScannedBatch
from fleetlink.wire import Record


@dataclass
class _Site:
    batches: Counter[str] = field(default_factory=Counter)
    records: int = 0
    dead_lettered: int = 0
    topics: Counter[str] = field(default_factory=Counter)


class DeliveryBoard:
    """This uplink's running delivery totals per site (thread-safe; at most ``max_sites`` sites and
    ``max_topics`` topics a site)."""

    def __init__(self, *, max_sites: int = 10_000, max_topics: int = 10_000) -> None:
        self.max_sites = max_sites
        self.max_topics = max_topics
        self._sites: dict[str, _Site] = {}
        self._lock = threading.Lock()

    def on_batch(
        self, site: str, status: str, topics: Mapping[str, int] | None = None, dead_lettered: int = 0
    ) -> None:
        """Count one answered batch of ``site``: its status, the records Kafka acknowledged per topic, its
        dead letters (beyond the bounds, a new site or topic is not counted)."""
        with self._lock:
            entry = self._sites.get(site)
            if entry is None:
                if len(self._sites) >= self.max_sites:
                    return
                entry = self._sites[site] = _Site()
            entry.batches[status] += 1
            entry.dead_lettered += dead_lettered
            for topic, n in (topics or {}).items():
                if topic in entry.topics or len(entry.topics) < self.max_topics:
                    entry.topics[topic] += n
                    entry.records += n

    def sites(self) -> list[str]:
        """The sites whose batches this uplink answered, sorted."""
        with self._lock:
            return sorted(self._sites)

    def figures(self, site: str) -> dict[str, Any] | None:
        """``{"batches": {status: n}, "records": n, "dead_lettered": n, "topics": {topic: n}}``
        (records Kafka acknowledged), or ``None`` for a site this uplink never served."""
        with self._lock:
            entry = self._sites.get(site)
            if entry is None:
                return None
            return {
                "batches": dict(entry.batches),
                "records": entry.records,
                "dead_lettered": entry.dead_lettered,
                "topics": dict(entry.topics),
            }


def acked_topics(records: Iterable[Record], dead_lettered: set[int]) -> Counter[str]:
    """Records per Kafka topic of a batch answered ``ok``, less the dead-lettered ones (by seq)."""
    return Counter(r.kafka_topic for r in records if r.seq not in dead_lettered)


def acked_scanned(scanned: ScannedBatch, dead_lettered: set[int]) -> Counter[str]:
    """``acked_topics`` of a natively scanned batch (counted natively)."""
    return Counter(scanned.acked_counts(list(dead_lettered)))
