"""The one small interface every component reports through.

Components call ``Metrics`` methods and never touch Prometheus: ``PrometheusMetrics`` exports
them, ``MetricsRecorder`` keeps them in memory for tests, ``NullMetrics`` drops them. Each method
feeds one family of ``fleetlink.common.metrics.families`` (see docs/metrics.md).

``stage`` is a stage's name (``throttle``, ``filter_2``), or ``None`` for the mapping as a whole.
Counts are increments; ``set_*`` methods set gauges from a snapshot.
"""

from __future__ import annotations

from typing import Protocol

from fleetlink.common.metrics.families import Family, family

HealthState = str  # "ok" | "degraded" | "failed" (fleetlink.common.metrics.health.State)
HEALTH_STATES: tuple[str, ...] = ("ok", "degraded", "failed")


class Metrics(Protocol):
    """What components report. Thread-safe in every implementation."""

    # mappings (edge)
    def on_received(self, mapping: str, n: int = 1) -> None: ...
    def on_emitted(self, mapping: str, stage: str | None = None, n: int = 1) -> None: ...
    def on_dropped(self, mapping: str, stage: str | None, reason: str, n: int = 1) -> None: ...
    def on_dead_letter(self, mapping: str, stage: str | None = None, n: int = 1) -> None: ...
    def on_gap(self, topic: str, n: int = 1) -> None: ...
    def on_lost_before_spool(self, robot: str, topic: str, n: int = 1) -> None: ...

    # the intake (edge)
    def on_intake_dropped(self, n: int = 1) -> None: ...
    def set_intake(self, *, queued: int, lag_s: float, rss_bytes: int, bound_bytes: int) -> None: ...

    # buffers and the WAN (edge)
    def on_spooled(self, n: int, nbytes: int, stream: str = "spool") -> None: ...
    def on_spool_dropped(self, stream: str, reason: str, n: int = 1) -> None: ...
    def on_sent(self, batches: int, records: int, nbytes: int) -> None: ...
    def on_acked(self, batches: int, records: int, latency_s: float | None = None) -> None: ...
    def on_ack_latencies(self, counts: tuple[int, ...], total_s: float) -> None: ...
    def on_wan_failure(self, reason: str, n: int = 1) -> None: ...
    def set_spool(
        self,
        stream: str,
        *,
        nbytes: int,
        capacity_bytes: int,
        depth: int,
        in_flight: int,
        oldest_age_s: float,
        damage_unacknowledged: int = 0,
    ) -> None: ...
    def set_wan(self, *, in_flight: int, link_up: bool) -> None: ...
    def set_robots(self, n: int) -> None: ...
    def on_admin_refused(self, reason: str) -> None: ...

    # uplink
    def on_ingested(self, site: str, status: str, records: int, dead_lettered: int = 0) -> None: ...
    def on_delivered(self, topic: str, ok: bool, latency_s: float) -> None: ...
    def on_refused(self, site: str, reason: str, *, batches: int = 0, records: int = 0) -> None: ...

    def on_registry_error(self, reason: str, n: int = 1) -> None: ...
    def set_command_lag(self, seconds: float) -> None: ...

    # repeater
    def on_command(self, command: str, outcome: str, n: int = 1) -> None: ...
    def on_forged_command(self, reason: str) -> None: ...
    def set_repeater(self, *, link_up: bool, active: int) -> None: ...

    # every process
    def set_health(self, state: HealthState) -> None: ...


class FamilyMetrics:
    """``Metrics`` written once on top of three primitives (increment, set, observe) that
    implementations provide for a ``Family`` and its label values."""

    def _inc(self, fam: Family, labels: tuple[str, ...], n: float) -> None:
        raise NotImplementedError

    def _set(self, fam: Family, labels: tuple[str, ...], value: float) -> None:
        raise NotImplementedError

    def _observe(self, fam: Family, labels: tuple[str, ...], value: float) -> None:
        raise NotImplementedError

    def _observe_buckets(self, fam: Family, counts: tuple[int, ...], total: float) -> None:
        raise NotImplementedError

    def _count(self, name: str, *labels: str, n: float = 1) -> None:
        if n > 0:
            self._inc(family(name), labels, n)

    # mappings ------------------------------------------------------------------------------
    def on_received(self, mapping: str, n: int = 1) -> None:
        self._count("fleetlink_mapping_received", mapping, n=n)

    def on_emitted(self, mapping: str, stage: str | None = None, n: int = 1) -> None:
        if stage is None:
            self._count("fleetlink_mapping_emitted", mapping, n=n)
        else:
            self._count("fleetlink_stage_emitted", mapping, stage, n=n)

    def on_dropped(self, mapping: str, stage: str | None, reason: str, n: int = 1) -> None:
        if stage is None:
            self._count("fleetlink_mapping_dropped", mapping, reason, n=n)
        else:
            self._count("fleetlink_stage_dropped", mapping, stage, reason, n=n)

    def on_dead_letter(self, mapping: str, stage: str | None = None, n: int = 1) -> None:
        self._count("fleetlink_mapping_dead_lettered", mapping, stage or "", n=n)

    def on_gap(self, topic: str, n: int = 1) -> None:
        self._count("fleetlink_sequence_gaps", topic, n=n)

    def on_lost_before_spool(self, robot: str, topic: str, n: int = 1) -> None:
        self._count("fleetlink_lost_before_spool", robot, topic, n=n)

    # the intake ---------------------------------------------------------------------------
    def on_intake_dropped(self, n: int = 1) -> None:
        self._count("fleetlink_intake_dropped_samples", n=n)

    def set_intake(self, *, queued: int, lag_s: float, rss_bytes: int, bound_bytes: int) -> None:
        self._set(family("fleetlink_intake_queued_samples"), (), queued)
        self._set(family("fleetlink_intake_lag_seconds"), (), lag_s)
        self._set(family("fleetlink_memory_resident_bytes"), (), rss_bytes)
        self._set(family("fleetlink_memory_bound_bytes"), (), bound_bytes)

    # buffers and the WAN -----------------------------------------------------------------
    def on_spooled(self, n: int, nbytes: int, stream: str = "spool") -> None:
        self._count("fleetlink_spool_appended_records", stream, n=n)
        self._count("fleetlink_spool_appended_bytes", stream, n=nbytes)

    def on_spool_dropped(self, stream: str, reason: str, n: int = 1) -> None:
        self._count("fleetlink_spool_dropped_records", stream, reason, n=n)

    def on_sent(self, batches: int, records: int, nbytes: int) -> None:
        self._count("fleetlink_wan_sent_batches", n=batches)
        self._count("fleetlink_wan_sent_records", n=records)
        self._count("fleetlink_wan_sent_bytes", n=nbytes)

    def on_acked(self, batches: int, records: int, latency_s: float | None = None) -> None:
        """``latency_s``: from sending to the ack (one observation); ``None`` when unknown. A
        component whose totals are read from snapshots (the edge) reports only the latency:
        ``on_acked(0, 0, latency_s)``."""
        self._count("fleetlink_wan_acked_batches", n=batches)
        self._count("fleetlink_wan_acked_records", n=records)
        if latency_s is not None:
            self._observe(family("fleetlink_wan_ack_latency_seconds"), (), max(0.0, latency_s))

    def on_ack_latencies(self, counts: tuple[int, ...], total_s: float) -> None:
        """Ack latencies the edge's senders measured and counted per bucket since the last look:
        ``counts[i]`` in bucket ``i`` of ``LATENCY_BUCKETS`` (the last: above them), summing to
        ``total_s`` seconds (``fleetlink_wan_ack_latency_seconds``)."""
        if any(counts):
            self._observe_buckets(family("fleetlink_wan_ack_latency_seconds"), counts, total_s)

    def on_wan_failure(self, reason: str, n: int = 1) -> None:
        self._count("fleetlink_wan_failures", reason, n=n)

    def set_spool(
        self,
        stream: str,
        *,
        nbytes: int,
        capacity_bytes: int,
        depth: int,
        in_flight: int,
        oldest_age_s: float,
        damage_unacknowledged: int = 0,
    ) -> None:
        labels = (stream,)
        self._set(family("fleetlink_spool_bytes"), labels, nbytes)
        self._set(family("fleetlink_spool_capacity_bytes"), labels, capacity_bytes)
        self._set(family("fleetlink_spool_depth_records"), labels, depth)
        self._set(family("fleetlink_spool_in_flight_records"), labels, in_flight)
        self._set(family("fleetlink_spool_oldest_age_seconds"), labels, oldest_age_s)
        self._set(family("fleetlink_spool_damage_unacknowledged"), labels, damage_unacknowledged)

    def set_wan(self, *, in_flight: int, link_up: bool) -> None:
        self._set(family("fleetlink_wan_in_flight_batches"), (), in_flight)
        self._set(family("fleetlink_wan_link_up"), (), 1.0 if link_up else 0.0)

    def set_robots(self, n: int) -> None:
        self._set(family("fleetlink_robots_registered"), (), n)

    def on_admin_refused(self, reason: str) -> None:
        self._count("fleetlink_admin_refused", reason)

    # uplink --------------------------------------------------------------------------------------
    def on_ingested(self, site: str, status: str, records: int, dead_lettered: int = 0) -> None:
        self._count("fleetlink_ingest_batches", site, status)
        self._count("fleetlink_ingest_records", site, n=records)
        self._count("fleetlink_ingest_dead_lettered", site, n=dead_lettered)

    def on_delivered(self, topic: str, ok: bool, latency_s: float) -> None:
        self._count("fleetlink_kafka_delivered", topic, "ok" if ok else "error")
        self._observe(family("fleetlink_kafka_delivery_latency_seconds"), (), max(0.0, latency_s))

    def on_refused(self, site: str, reason: str, *, batches: int = 0, records: int = 0) -> None:
        if batches:
            self._count("fleetlink_ingest_refused_batches", site, reason, n=batches)
        if records:
            self._count("fleetlink_ingest_refused_records", site, reason, n=records)

    def on_registry_error(self, reason: str, n: int = 1) -> None:
        self._count("fleetlink_registry_errors", reason, n=n)

    def set_command_lag(self, seconds: float) -> None:
        self._set(family("fleetlink_command_lag_seconds"), (), max(0.0, seconds))

    # repeater --------------------------------------------------------------------------------
    def on_command(self, command: str, outcome: str, n: int = 1) -> None:
        self._count("fleetlink_commands", command, outcome, n=n)

    def on_forged_command(self, reason: str) -> None:
        self._count("fleetlink_commands_forged", reason)

    def set_repeater(self, *, link_up: bool, active: int) -> None:
        self._set(family("fleetlink_repeater_link_up"), (), 1.0 if link_up else 0.0)
        self._set(family("fleetlink_repeater_active_commands"), (), active)

    # every process ---------------------------------------------------------------------------
    def set_health(self, state: HealthState) -> None:
        fam = family("fleetlink_health")
        for known in HEALTH_STATES:
            self._set(fam, (known,), 1.0 if known == state else 0.0)


class NullMetrics(FamilyMetrics):
    """Drops everything (the default when a component is given no metrics)."""

    def _inc(self, fam: Family, labels: tuple[str, ...], n: float) -> None:  # noqa: ARG002
        return None

    def _set(self, fam: Family, labels: tuple[str, ...], value: float) -> None:  # noqa: ARG002
        return None

    def _observe(self, fam: Family, labels: tuple[str, ...], value: float) -> None:  # noqa: ARG002
        return None

    def _observe_buckets(self, fam: Family, counts: tuple[int, ...], total: float) -> None:  # noqa: ARG002
        return None
