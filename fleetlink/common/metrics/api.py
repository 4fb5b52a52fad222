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
    def on_received(self, mapping: str, n: int = 1) -> None:
        """Count ``n`` ROS samples ``mapping`` received."""

    def on_emitted(self, mapping: str, stage: str | None = None, n: int = 1) -> None:
        """Count ``n`` outputs of ``stage``, or (``stage`` None) records the mapping handed to its buffer."""

    def on_dropped(self, mapping: str, stage: str | None, reason: str, n: int = 1) -> None:
        """Count ``n`` samples ``stage`` (None: the mapping as a whole) dropped on purpose, for ``reason``."""

    def on_dead_letter(self, mapping: str, stage: str | None = None, n: int = 1) -> None:
        """Count ``n`` samples or records dead-lettered; ``stage`` is where they failed, if known."""

    def on_gap(self, topic: str, n: int = 1) -> None:
        """Count ``n`` ROS messages missing from the publishers' sequence numbers on ``topic``."""

    def on_unmapped(self, topic: str, n: int = 1) -> None:
        """Count ``n`` ROS messages received on ``topic`` that no mapping took."""

    def on_lost_before_spool(self, robot: str, topic: str, n: int = 1) -> None:
        """Count ``n`` messages ``robot`` published on ``topic`` that never reached the spool."""

    # the intake (edge)
    def on_intake_dropped(self, n: int = 1) -> None:
        """Count ``n`` samples the full intake could not take."""

    def set_intake(self, *, queued: int, lag_s: float, rss_bytes: int, bound_bytes: int) -> None:
        """Set the intake gauges: samples queued, the oldest one's wait (s), resident memory and its bound."""

    # buffers and the WAN (edge)
    def on_spooled(self, n: int, nbytes: int, stream: str = "spool") -> None:
        """Count ``n`` records and ``nbytes`` payload bytes appended to buffer ``stream``."""

    def on_spool_dropped(self, stream: str, reason: str, n: int = 1) -> None:
        """Count ``n`` records buffer ``stream`` lost, for ``reason``."""

    def on_sent(self, batches: int, records: int, nbytes: int) -> None:
        """Count batches, records and encoded bytes sent to the uplink (retries included)."""

    def on_acked(self, batches: int, records: int, latency_s: float | None = None) -> None:
        """Count batches and records acknowledged, and one ack latency in seconds unless it is None."""

    def on_ack_latencies(self, counts: tuple[int, ...], total_s: float) -> None:
        """Add ack latencies counted per bucket of ``LATENCY_BUCKETS``, summing to ``total_s`` seconds."""

    def on_wan_failure(self, reason: str, n: int = 1) -> None:
        """Count ``n`` batches that must be sent again, for ``reason``."""

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
        """Set the gauges of buffer ``stream``: its fill, backlog, oldest age and unacknowledged damage."""

    def set_wan(self, *, in_flight: int, link_up: bool) -> None:
        """Set the batches in flight and whether the uplink answered recently."""

    def set_robots(self, n: int) -> None:
        """Set the number of robots registered at this edge."""

    def on_admin_refused(self, reason: str) -> None:
        """Count one admin request refused, for ``reason``."""

    # uplink
    def on_ingested(self, site: str, status: str, records: int, dead_lettered: int = 0) -> None:
        """Count one batch from ``site`` with ``status``, its records and those dead-lettered."""

    def on_delivered(self, topic: str, ok: bool, latency_s: float) -> None:
        """Count one Kafka delivery report for ``topic`` and observe its latency in seconds."""

    def on_refused(self, site: str, reason: str, *, batches: int = 0, records: int = 0) -> None:
        """Count batches refused whole and records sent to the refused topic, for ``site`` and ``reason``."""

    def on_registry_error(self, reason: str, n: int = 1) -> None:
        """Count ``n`` schema registry requests that failed, for ``reason``."""

    def set_command_lag(self, seconds: float) -> None:
        """Set the age in seconds of the oldest command not yet settled by a repeater."""

    # repeater
    def on_command(self, command: str, outcome: str, n: int = 1) -> None:
        """Count ``n`` commands handled with ``outcome``; ``command`` is a ROS topic, empty for one taken."""

    def on_forged_command(self, reason: str) -> None:
        """Count one command envelope refused unread for ``reason`` (not signed by a trusted key)."""

    def set_repeater(self, *, link_up: bool, active: int) -> None:
        """Set whether an uplink answers the repeater's status link and how many commands it repeats."""

    # every process
    def set_health(self, state: HealthState) -> None:
        """Set the process's health state: 1 for ``state``, 0 for the other known states."""


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
        """Add ``n`` to ``fleetlink_mapping_received``."""
        self._count("fleetlink_mapping_received", mapping, n=n)

    def on_emitted(self, mapping: str, stage: str | None = None, n: int = 1) -> None:
        """Add ``n`` to ``fleetlink_stage_emitted`` (``stage`` None: ``fleetlink_mapping_emitted``)."""
        if stage is None:
            self._count("fleetlink_mapping_emitted", mapping, n=n)
        else:
            self._count("fleetlink_stage_emitted", mapping, stage, n=n)

    def on_dropped(self, mapping: str, stage: str | None, reason: str, n: int = 1) -> None:
        """Add ``n`` to ``fleetlink_stage_dropped`` (``stage`` None: ``fleetlink_mapping_dropped``)."""
        if stage is None:
            self._count("fleetlink_mapping_dropped", mapping, reason, n=n)
        else:
            self._count("fleetlink_stage_dropped", mapping, stage, reason, n=n)

    def on_dead_letter(self, mapping: str, stage: str | None = None, n: int = 1) -> None:
        """Add ``n`` to ``fleetlink_mapping_dead_lettered`` (an empty ``stage`` label when None)."""
        self._count("fleetlink_mapping_dead_lettered", mapping, stage or "", n=n)

    def on_gap(self, topic: str, n: int = 1) -> None:
        """Add ``n`` to ``fleetlink_sequence_gaps``."""
        self._count("fleetlink_sequence_gaps", topic, n=n)

    def on_unmapped(self, topic: str, n: int = 1) -> None:
        """Add ``n`` to ``fleetlink_unmapped_samples``."""
        self._count("fleetlink_unmapped_samples", topic, n=n)

    def on_lost_before_spool(self, robot: str, topic: str, n: int = 1) -> None:
        """Add ``n`` to ``fleetlink_lost_before_spool``."""
        self._count("fleetlink_lost_before_spool", robot, topic, n=n)

    # the intake ---------------------------------------------------------------------------
    def on_intake_dropped(self, n: int = 1) -> None:
        """Add ``n`` to ``fleetlink_intake_dropped_samples``."""
        self._count("fleetlink_intake_dropped_samples", n=n)

    def set_intake(self, *, queued: int, lag_s: float, rss_bytes: int, bound_bytes: int) -> None:
        """Set ``fleetlink_intake_queued_samples``, ``_lag_seconds`` and the ``fleetlink_memory_*`` gauges."""
        self._set(family("fleetlink_intake_queued_samples"), (), queued)
        self._set(family("fleetlink_intake_lag_seconds"), (), lag_s)
        self._set(family("fleetlink_memory_resident_bytes"), (), rss_bytes)
        self._set(family("fleetlink_memory_bound_bytes"), (), bound_bytes)

    # buffers and the WAN -----------------------------------------------------------------
    def on_spooled(self, n: int, nbytes: int, stream: str = "spool") -> None:
        """Add to ``fleetlink_spool_appended_records`` and ``fleetlink_spool_appended_bytes``."""
        self._count("fleetlink_spool_appended_records", stream, n=n)
        self._count("fleetlink_spool_appended_bytes", stream, n=nbytes)

    def on_spool_dropped(self, stream: str, reason: str, n: int = 1) -> None:
        """Add ``n`` to ``fleetlink_spool_dropped_records``."""
        self._count("fleetlink_spool_dropped_records", stream, reason, n=n)

    def on_sent(self, batches: int, records: int, nbytes: int) -> None:
        """Add to the ``fleetlink_wan_sent_*`` counters (batches, records, bytes)."""
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
        """Add ``n`` to ``fleetlink_wan_failures``."""
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
        """Set the ``fleetlink_spool_*`` gauges of ``stream``."""
        labels = (stream,)
        self._set(family("fleetlink_spool_bytes"), labels, nbytes)
        self._set(family("fleetlink_spool_capacity_bytes"), labels, capacity_bytes)
        self._set(family("fleetlink_spool_depth_records"), labels, depth)
        self._set(family("fleetlink_spool_in_flight_records"), labels, in_flight)
        self._set(family("fleetlink_spool_oldest_age_seconds"), labels, oldest_age_s)
        self._set(family("fleetlink_spool_damage_unacknowledged"), labels, damage_unacknowledged)

    def set_wan(self, *, in_flight: int, link_up: bool) -> None:
        """Set ``fleetlink_wan_in_flight_batches`` and ``fleetlink_wan_link_up`` (1 or 0)."""
        self._set(family("fleetlink_wan_in_flight_batches"), (), in_flight)
        self._set(family("fleetlink_wan_link_up"), (), 1.0 if link_up else 0.0)

    def set_robots(self, n: int) -> None:
        """Set ``fleetlink_robots_registered``."""
        self._set(family("fleetlink_robots_registered"), (), n)

    def on_admin_refused(self, reason: str) -> None:
        """Add one to ``fleetlink_admin_refused``."""
        self._count("fleetlink_admin_refused", reason)

    # uplink --------------------------------------------------------------------------------------
    def on_ingested(self, site: str, status: str, records: int, dead_lettered: int = 0) -> None:
        """Add to ``fleetlink_ingest_batches``, ``_records`` and ``_dead_lettered``."""
        self._count("fleetlink_ingest_batches", site, status)
        self._count("fleetlink_ingest_records", site, n=records)
        self._count("fleetlink_ingest_dead_lettered", site, n=dead_lettered)

    def on_delivered(self, topic: str, ok: bool, latency_s: float) -> None:
        """Add to ``fleetlink_kafka_delivered`` and observe ``fleetlink_kafka_delivery_latency_seconds``."""
        self._count("fleetlink_kafka_delivered", topic, "ok" if ok else "error")
        self._observe(family("fleetlink_kafka_delivery_latency_seconds"), (), max(0.0, latency_s))

    def on_refused(self, site: str, reason: str, *, batches: int = 0, records: int = 0) -> None:
        """Add to ``fleetlink_ingest_refused_batches`` and ``fleetlink_ingest_refused_records``."""
        if batches:
            self._count("fleetlink_ingest_refused_batches", site, reason, n=batches)
        if records:
            self._count("fleetlink_ingest_refused_records", site, reason, n=records)

    def on_registry_error(self, reason: str, n: int = 1) -> None:
        """Add ``n`` to ``fleetlink_registry_errors``."""
        self._count("fleetlink_registry_errors", reason, n=n)

    def set_command_lag(self, seconds: float) -> None:
        """Set ``fleetlink_command_lag_seconds`` (negative values as 0)."""
        self._set(family("fleetlink_command_lag_seconds"), (), max(0.0, seconds))

    # repeater --------------------------------------------------------------------------------
    def on_command(self, command: str, outcome: str, n: int = 1) -> None:
        """Add ``n`` to ``fleetlink_commands``."""
        self._count("fleetlink_commands", command, outcome, n=n)

    def on_forged_command(self, reason: str) -> None:
        """Add one to ``fleetlink_commands_forged``."""
        self._count("fleetlink_commands_forged", reason)

    def set_repeater(self, *, link_up: bool, active: int) -> None:
        """Set ``fleetlink_repeater_link_up`` (1 or 0) and ``fleetlink_repeater_active_commands``."""
        self._set(family("fleetlink_repeater_link_up"), (), 1.0 if link_up else 0.0)
        self._set(family("fleetlink_repeater_active_commands"), (), active)

    # every process ---------------------------------------------------------------------------
    def set_health(self, state: HealthState) -> None:
        """Set ``fleetlink_health``: 1 for ``state``, 0 for every other state in ``HEALTH_STATES``."""
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
