"""Edge snapshots -> metrics and health (pull model: runs when someone looks, not per record).

The agent keeps running totals; on each ``/metrics`` scrape, ``/health`` request or Zenoh health
query, ``EdgeTelemetry.observe`` turns the increase since the last look into ``Metrics`` calls,
sets the gauges and assesses health. Nothing is added to the per-record path. Thread-safe.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from fleetlink.common.metrics import CounterDeltas, Health, Metrics, RecentIncrease
from fleetlink.common.metrics.buckets import BucketDeltas
from fleetlink.edge.admin.backend import EdgeSnapshot
from fleetlink.edge.admin.health import HealthRules, assess

_STAGE_DROPS = (("dropped", "dropped"), ("late", "late"), ("errors", "error"))
_SPOOL_DROPS = (
    ("dropped_oldest", "dropped_oldest"),
    ("dropped_newest", "dropped_newest"),
    ("corrupt_skipped", "corrupt"),
    ("lost_missing", "missing"),
    ("block_timeouts", "block_timeout"),
)


class EdgeTelemetry:
    """Turns edge snapshots into metrics and health, counting increases since the last look."""

    def __init__(
        self,
        metrics: Metrics,
        *,
        rules: HealthRules | None = None,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.metrics = metrics
        self.rules = rules or HealthRules()
        self._clock = clock
        self._created = clock()
        self._deltas = CounterDeltas()
        self._latency = BucketDeltas()
        self._recent: dict[str, RecentIncrease] = {}
        self._lock = threading.Lock()

    def observe(self, snapshot: EdgeSnapshot, *, robots: int) -> Health:
        """Report what changed since the last call; returns the edge's health now."""
        with self._lock:
            now = self._clock()
            self._counters(snapshot)
            self._gauges(snapshot, now, robots)
            recent = self._dead_letters(snapshot, now)
            health = assess(snapshot, recent, now_ms=int(now * 1000), robots=robots, rules=self.rules)
            self.metrics.set_health(health.state)
            return health

    def _counters(self, snapshot: EdgeSnapshot) -> None:
        m, d = self.metrics, self._deltas.delta
        intake = snapshot.intake
        m.on_intake_dropped(d(("intake_dropped",), intake.dropped))
        m.set_intake(
            queued=intake.queued,
            lag_s=intake.lag_s,
            rss_bytes=intake.rss_bytes,
            bound_bytes=intake.bound_bytes,
        )
        for name, counts in snapshot.mappings.items():
            m.on_received(name, d(("received", name), counts.received))
            m.on_emitted(name, None, d(("emitted", name), counts.emitted))
            m.on_dropped(name, None, "pipeline", d(("dropped", name), counts.dropped))
            m.on_dropped(name, None, "type_mismatch", d(("type_mismatch", name), counts.type_mismatch))
            m.on_dead_letter(name, None, d(("dead_lettered", name), counts.dead_lettered))
            for stage, values in counts.stages.items():
                m.on_emitted(name, stage, d(("stage_emitted", name, stage), values.get("emitted", 0)))
                for field, reason in _STAGE_DROPS:
                    n = d((f"stage_{field}", name, stage), values.get(field, 0))
                    m.on_dropped(name, stage, reason, n)
        for buffer in snapshot.buffers:
            stats = buffer.stats
            stream = stats.stream
            m.on_spooled(
                d(("appended", stream), stats.appended),
                d(("appended_bytes", stream), buffer.appended_bytes),
                stream,
            )
            for field, reason in _SPOOL_DROPS:
                m.on_spool_dropped(stream, reason, d((field, stream), getattr(stats, field)))
        for stream, wan in snapshot.wan.items():
            m.on_sent(
                d(("batches_sent", stream), wan.batches_sent),
                d(("records_sent", stream), wan.records_sent),
                d(("bytes_sent", stream), wan.bytes_sent),
            )
            m.on_acked(
                d(("batches_acked", stream), wan.batches_acked),
                d(("records_acked", stream), wan.records_acked),
            )
            m.on_wan_failure("retry", d(("batches_retried", stream), wan.batches_retried))
            latency = self._latency.delta(stream, wan.ack_latency)
            m.on_ack_latencies(latency.counts, latency.sum_s)
        for topic, missing in snapshot.sequence_gaps.items():
            m.on_gap(topic, d(("gap", topic), missing))
        for topic, n in snapshot.unmapped.items():
            m.on_unmapped(topic, d(("unmapped", topic), n))
        for robot, topics in snapshot.lost_before_spool.items():
            for topic, lost in topics.items():
                m.on_lost_before_spool(robot, topic, d(("lost_before_spool", robot, topic), lost))

    def _gauges(self, snapshot: EdgeSnapshot, now: float, robots: int) -> None:
        now_ms = int(now * 1000)
        for buffer in snapshot.buffers:
            stats = buffer.stats
            self.metrics.set_spool(
                stats.stream,
                nbytes=stats.bytes,
                capacity_bytes=buffer.capacity_bytes,
                depth=stats.depth,
                in_flight=stats.in_flight,
                oldest_age_s=stats.oldest_age_ms(now_ms) / 1000,
                damage_unacknowledged=stats.damage_unacknowledged,
            )
        in_flight = sum(w.in_flight for w in snapshot.wan.values())
        if snapshot.wan_link_up is not None or snapshot.wan:
            self.metrics.set_wan(in_flight=in_flight, link_up=snapshot.wan_link_up is not False)
        self.metrics.set_robots(robots)

    def _dead_letters(self, snapshot: EdgeSnapshot, now: float) -> dict[str, int]:
        out = {}
        for name, counts in snapshot.mappings.items():
            tracker = self._recent.get(name)
            if tracker is None:
                tracker = self._recent[name] = RecentIncrease(
                    self.rules.dead_letter_window_s, created_s=self._created
                )
            out[name] = tracker.update(now, counts.dead_lettered)
        for gone in set(self._recent) - set(snapshot.mappings):
            del self._recent[gone]
        return out
