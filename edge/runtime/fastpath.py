"""The per-sample fast path: a topic whose mappings all take CDR straight to Avro (pure).

For a mapping without stages whose Kafka topic and key read no message field, everything about
a record but its value, timestamp and ROS sequence number is fixed by (topic, ROS type, type
hash, mapping). ``FastPlan`` holds that fixed part once per such combination: the converter,
the single-object header of the schema and the encoded payload tail (``PayloadTemplate``), so
each sample costs one conversion and one ``struct.pack`` per mapping. Anything unusual (a value
that does not convert, one too large, a sequence number below zero) is handed back to the
general path, which makes the same record or dead letter it always did.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from fleetlink.edge.mapping import BoundMapping, Delivery
from fleetlink.edge.runtime.outgoing import MappingCounters, Outgoing
from fleetlink.roswire.subscriber import RosSample
from fleetlink.schemas.codec import Codec
from fleetlink.schemas.errors import SchemaError
from fleetlink.wire import PayloadTemplate


@dataclass(frozen=True, slots=True)
class Lane:
    """One mapping of a fast plan."""

    bound: BoundMapping
    counters: MappingCounters
    codec: Codec
    """The type's codec: ``convert`` is its ``cdr_to_avro``, the native path compiles its layout."""
    convert: Callable[[bytes], bytes]
    head: bytes
    """``C3 01`` + the schema fingerprint: the single-object header."""
    template: PayloadTemplate
    delivery: Delivery
    linger_s: float | None = None


@dataclass(frozen=True, slots=True)
class FastPlan:
    """The lanes of one data key (topic, type, hash) for one mapping-table snapshot (``bounds``).

    ``lanes`` is None when some mapping of the topic needs the general path (then the whole
    sample takes it); ``mismatched`` are mappings declaring another type (counted only).
    """

    topic: str
    bounds: Sequence[BoundMapping]
    lanes: tuple[Lane, ...] | None
    mismatched: tuple[MappingCounters, ...] = ()


Slow = Callable[[BoundMapping, RosSample, int, list[Outgoing]], None]
"""The general path for one mapping and one sample (``RecordMaker._one(bound, sample, now_ns, out)``)."""


def run_plan(
    plan: FastPlan, sample: RosSample, max_value_bytes: int, slow: Slow, now_ns: int
) -> list[Outgoing]:
    """The records of ``sample`` through the fast lanes of ``plan`` (``plan.lanes`` is set)."""
    out: list[Outgoing] = []
    for counters in plan.mismatched:
        counters.received += 1
        counters.type_mismatch += 1
    lanes = plan.lanes or ()
    payload = sample.payload
    seq = sample.seq
    stamp_ns = sample.source_ts_ns if sample.source_ts_ns else sample.received_ns
    timestamp_ms = stamp_ns // 1_000_000
    for lane in lanes:
        lane.counters.received += 1
        if seq is not None and seq < 0:
            slow(lane.bound, sample, now_ns, out)
            continue
        try:
            value = lane.head + lane.convert(payload)
        except SchemaError:
            slow(lane.bound, sample, now_ns, out)  # makes the dead letter, with the reason
            continue
        if len(value) > max_value_bytes:
            slow(lane.bound, sample, now_ns, out)
            continue
        out.append(Outgoing(lane.delivery, lane.template.payload(value, timestamp_ms, seq), lane.linger_s))
        lane.counters.emitted += 1
    return out
