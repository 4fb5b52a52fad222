"""Exactly-once robot -> Kafka: a stream's records and its high-water mark in one transaction.

An edge whose spool is ``delivery: exactly_once`` puts its spool's origin in every batch
(``fleetlink.wire.Batch.origin``). For each (site, edge, stream) the uplink keeps a transactional
producer whose ``transactional.id`` names that stream; registering it fences any other producer
of the same stream (another uplink, or this one before a restart). A batch's records above the
stream's mark, and the new mark, are written in one Kafka transaction; records at or below the
mark were written before (the edge sent the batch again) and are skipped. Marks live in a
compacted topic (``topics.marks``), read back when a producer takes a stream over.
"""

from fleetlink.uplink.exactly_once.marks import Mark, MarkKey, above, at_or_below, decode_mark, encode_mark
from fleetlink.uplink.exactly_once.marks_reader import MarksReader
from fleetlink.uplink.exactly_once.writer import ExactlyOnceWriter, Pending, TxnSink

__all__ = [
    "ExactlyOnceWriter",
    "Mark",
    "MarkKey",
    "MarksReader",
    "Pending",
    "TxnSink",
    "above",
    "at_or_below",
    "decode_mark",
    "encode_mark",
]
