"""The Kafka record headers fleetlink writes: one definition for the edge that sets them and the
uplink that checks them (docs/kafka-records.md)."""

from __future__ import annotations

from fleetlink.wire.robot_events import EDGE_HEADER, ROBOT_HEADER, SITE_HEADER

__all__ = ["EDGE_HEADER", "ROBOT_HEADER", "SITE_HEADER"]

SOURCE_TOPIC = "fleetlink.source_topic"
ROS_TYPE = "fleetlink.ros_type"
TYPE_HASH = "fleetlink.type_hash"
SEQ = "fleetlink.seq"
MAPPING = "fleetlink.mapping"
ROS_KEY = "fleetlink.ros_key"
"""The Zenoh key a dead-lettered sample arrived on."""

DLQ_STAGE = "fleetlink.dlq.stage"
DLQ_REASON = "fleetlink.dlq.reason"
DLQ_TOPIC = "fleetlink.dlq.topic"
DLQ_SIZE = "fleetlink.dlq.size"
DLQ_SHA256 = "fleetlink.dlq.sha256"
DLQ_TRUNCATED = "fleetlink.dlq.truncated"
DLQ_PREFIX = "fleetlink.dlq."

EDGE_DEAD_LETTER: frozenset[str] = frozenset(
    (
        SITE_HEADER,
        EDGE_HEADER,
        ROBOT_HEADER,
        SOURCE_TOPIC,
        ROS_TYPE,
        TYPE_HASH,
        SEQ,
        MAPPING,
        ROS_KEY,
        DLQ_STAGE,
        DLQ_REASON,
        DLQ_TOPIC,
        DLQ_SIZE,
        DLQ_SHA256,
        DLQ_TRUNCATED,
    )
)
"""Every header an edge's dead letter may carry; the uplink refuses one carrying another."""
MAX_HEADER_VALUE = 4096
"""The longest header value an edge's dead letter may carry (reasons are cut at 2,000 bytes)."""
