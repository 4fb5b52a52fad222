"""How large a record is for Kafka: the one measure the uplink's limit and the edge's check share.

librdkafka refuses a record (``MSG_SIZE_TOO_LARGE``, before it is sent) when its largest possible
v2 wire size passes the producer's ``message.max.bytes``: a fixed overhead of varints, the key,
the value and every header's name and value with their length varints. The uplink tells the
edge its producer's limit in every acknowledgement (``Ack.max_record_bytes``); the edge measures
each record the same way, with the value as the uplink will produce it, and keeps the ones that
would not fit off the WAN.
"""

from __future__ import annotations

from collections.abc import Iterable

RECORD_OVERHEAD = 36
"""librdkafka's ``RD_KAFKAP_MESSAGE_V2_MAX_OVERHEAD``: length, attributes, timestamp delta,
offset delta, key length, value length and header count, each at its longest varint."""
HEADER_OVERHEAD = 10
"""The two length varints of one header, at their longest."""
DEFAULT_MAX_RECORD_BYTES = 1_000_000
"""librdkafka's default ``message.max.bytes``, and the uplink's (``kafka.message_max_bytes``)."""
SINGLE_OBJECT_EXTRA = 5
"""A single-object value (10-byte header) is 5 bytes longer than the Confluent-framed one the
uplink produces (5-byte header)."""


def kafka_record_bytes(key_len: int, value_len: int, headers: Iterable[tuple[str, bytes]]) -> int:
    """The size librdkafka checks against ``message.max.bytes`` (an upper bound of the wire size)."""
    size = RECORD_OVERHEAD + key_len + value_len
    for name, value in headers:
        size += HEADER_OVERHEAD + len(name.encode("utf-8")) + len(value)
    return size
