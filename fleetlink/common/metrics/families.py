"""Every metric fleetlink exports: name, kind, labels and meaning, in one table.

The Prometheus exporter and the in-memory recorder are both built from this table, and
docs/metrics.md documents each entry (a unit test keeps them in step). Counter names are given
without the ``_total`` suffix the Prometheus exposition adds.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

Kind = Literal["counter", "gauge", "histogram"]
Component = Literal["edge", "uplink", "repeater", "any"]
COMPONENTS: tuple[str, ...] = ("edge", "uplink", "repeater")

LATENCY_BUCKETS: tuple[float, ...] = (
    0.001,
    0.0025,
    0.005,
    0.01,
    0.025,
    0.05,
    0.1,
    0.25,
    0.5,
    1.0,
    2.5,
    5.0,
    10.0,
    30.0,
    60.0,
)
"""Seconds: from a loopback round trip to a WAN outage that a retry bridged."""


@dataclass(frozen=True, slots=True)
class Family:
    """One exported metric: its name, kind, label names, help text and the process that exports it."""

    name: str
    kind: Kind
    labels: tuple[str, ...]
    help: str
    component: Component = "any"
    """The process that exports it (``any``: every process); a process exports its own alone."""

    @property
    def exposed(self) -> str:
        """The sample name a scraper sees (counters get ``_total``)."""
        return self.name + "_total" if self.kind == "counter" else self.name


def _c(name: str, labels: tuple[str, ...], text: str) -> Family:
    return Family(name, "counter", labels, text)


def _g(name: str, labels: tuple[str, ...], text: str) -> Family:
    return Family(name, "gauge", labels, text)


def _h(name: str, text: str) -> Family:
    return Family(name, "histogram", (), text)


def _of(component: Component, *families: Family) -> tuple[Family, ...]:
    return tuple(Family(f.name, f.kind, f.labels, f.help, component) for f in families)


_EDGE: tuple[Family, ...] = (
    # -- mappings (edge) ---------------------------------------------------------------------
    _c("fleetlink_mapping_received", ("mapping",), "ROS samples a mapping received"),
    _c(
        "fleetlink_mapping_emitted", ("mapping",), "Records a mapping handed to its buffer (after its stages)"
    ),
    _c(
        "fleetlink_mapping_dropped",
        ("mapping", "reason"),
        "Samples a mapping dropped on purpose (reason: pipeline, type_mismatch)",
    ),
    _c(
        "fleetlink_mapping_dead_lettered",
        ("mapping", "stage"),
        "Samples or records a mapping sent to the dead-letter topic (stage where it failed, if known)",
    ),
    _c("fleetlink_stage_emitted", ("mapping", "stage"), "Outputs of one stage of a mapping"),
    _c(
        "fleetlink_stage_dropped",
        ("mapping", "stage", "reason"),
        "Samples one stage dropped (reason: dropped, late, error)",
    ),
    _c("fleetlink_sequence_gaps", ("topic",), "ROS messages missing from a publisher's sequence numbers"),
    _c(
        "fleetlink_unmapped_samples",
        ("topic",),
        "ROS messages received that no mapping took (a robot not registered, or not yet)",
    ),
    _c(
        "fleetlink_lost_before_spool",
        ("robot", "topic"),
        "ROS messages a publisher sent that never reached the spool: the edge was stopped or crashed "
        "(counted from each publisher's first message after a restart)",
    ),
    # -- the intake (edge): between receiving a sample and spooling its records --------------
    _c(
        "fleetlink_intake_dropped_samples", (), "Samples the full intake could not take (counted, never held)"
    ),
    _g("fleetlink_intake_queued_samples", (), "Samples received and not yet turned into records"),
    _g(
        "fleetlink_intake_lag_seconds",
        (),
        "How long the oldest sample taken last had waited since it arrived",
    ),
    _g("fleetlink_memory_resident_bytes", (), "The process's resident memory"),
    _g("fleetlink_memory_bound_bytes", (), "The most the edge's configuration lets it hold (docs/edge.md)"),
    # -- buffers and the WAN (edge) --------------------------------------------------------
    _c("fleetlink_spool_appended_records", ("stream",), "Records appended to a buffer"),
    _c("fleetlink_spool_appended_bytes", ("stream",), "Bytes appended to a buffer"),
    _c(
        "fleetlink_spool_dropped_records",
        ("stream", "reason"),
        "Records a buffer lost (reason: dropped_oldest, dropped_newest, corrupt, missing, block_timeout)",
    ),
    _g(
        "fleetlink_spool_damage_unacknowledged",
        ("stream",),
        "Damage findings in a spool awaiting an operator's acknowledgement",
    ),
    _g("fleetlink_spool_bytes", ("stream",), "Bytes held by a buffer (unacknowledged records)"),
    _g("fleetlink_spool_capacity_bytes", ("stream",), "The buffer's size limit in bytes"),
    _g("fleetlink_spool_depth_records", ("stream",), "Unacknowledged records held (in flight included)"),
    _g("fleetlink_spool_in_flight_records", ("stream",), "Records sent and not yet acknowledged"),
    _g("fleetlink_spool_oldest_age_seconds", ("stream",), "Age of the oldest unacknowledged record"),
    _c("fleetlink_wan_sent_batches", (), "Batches sent to the uplink (retries included)"),
    _c("fleetlink_wan_sent_records", (), "Records sent to the uplink (retries included)"),
    _c("fleetlink_wan_sent_bytes", (), "Encoded batch bytes sent to the uplink"),
    _c("fleetlink_wan_acked_batches", (), "Batches the uplink acknowledged (in Kafka)"),
    _c("fleetlink_wan_acked_records", (), "Records the uplink acknowledged (in Kafka)"),
    _c(
        "fleetlink_wan_failures",
        ("reason",),
        "Batches that must be sent again (reason: timeout, error, refused)",
    ),
    _g("fleetlink_wan_in_flight_batches", (), "Batches sent and not yet answered"),
    _g("fleetlink_wan_link_up", (), "1 when the uplink answered recently, else 0"),
    _h("fleetlink_wan_ack_latency_seconds", "From sending a batch to its acknowledgement"),
    _g("fleetlink_robots_registered", (), "Robots registered at this edge"),
    _c(
        "fleetlink_admin_refused",
        ("reason",),
        "Admin requests refused (reason: wrong_token, locked_out, read_only)",
    ),
)
_UPLINK: tuple[Family, ...] = (
    _c(
        "fleetlink_ingest_batches",
        ("site", "status"),
        "Batches received from edges (status: ok, error, refused)",
    ),
    _c("fleetlink_ingest_records", ("site",), "Records received from edges"),
    _c("fleetlink_ingest_dead_lettered", ("site",), "Records the uplink sent to the dead-letter topic"),
    _c(
        "fleetlink_ingest_refused_batches",
        ("site", "reason"),
        "Batches refused whole, nothing produced (reason: identity, headers, schema)",
    ),
    _c(
        "fleetlink_ingest_refused_records",
        ("site", "reason"),
        "Records written to the refused topic instead of theirs (reason: topic, registration)",
    ),
    _c("fleetlink_kafka_delivered", ("topic", "result"), "Kafka delivery reports (result: ok, error)"),
    _h("fleetlink_kafka_delivery_latency_seconds", "From produce() to Kafka's delivery report"),
    _c(
        "fleetlink_registry_errors",
        ("reason",),
        "Schema registry requests that failed (reason: unavailable, incompatible, refused)",
    ),
    _g(
        "fleetlink_command_lag_seconds",
        (),
        "Age of the oldest command read from Kafka and not yet settled by a repeater",
    ),
)
_REPEATER: tuple[Family, ...] = (
    _c(
        "fleetlink_commands",
        ("command", "outcome"),
        "Commands handled (outcome: published, repeated, expired, refused)",
    ),
    _c(
        "fleetlink_commands_forged",
        ("reason",),
        "Command envelopes refused unread: not signed by a trusted key for this site (reason: "
        "unsigned, unknown_key, bad_signature, other_site)",
    ),
    _g("fleetlink_repeater_link_up", (), "1 while the uplink answers the repeater's status link, else 0"),
    _g("fleetlink_repeater_active_commands", (), "Commands the repeater repeats now (their lease holds)"),
)
_ANY: tuple[Family, ...] = (
    _g("fleetlink_health", ("state",), "1 for the process's current health state (ok, degraded, failed)"),
    _g("fleetlink_build_info", ("component", "version"), "Always 1; labels name the process and version"),
)

FAMILIES: tuple[Family, ...] = (
    *_of("edge", *_EDGE),
    *_of("uplink", *_UPLINK),
    *_of("repeater", *_REPEATER),
    *_ANY,
)

BY_NAME: dict[str, Family] = {f.name: f for f in FAMILIES}


def families_of(component: str) -> tuple[Family, ...]:
    """The families ``component`` exports: its own and those of every process."""
    return tuple(f for f in FAMILIES if f.component in (component, "any"))


def family(name: str) -> Family:
    """Look a family up by its name, with or without the exposed ``_total`` suffix."""
    found = BY_NAME.get(name) or BY_NAME.get(name.removesuffix("_total"))
    if found is None:
        raise KeyError(f"no metric named {name!r}")
    return found
