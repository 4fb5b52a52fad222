"""The registration event contract: the Avro schema of a robot (de)registration, and the headers
that name who sent a record.

The edge writes one ``RobotEvent`` per change to the registrations topic (``fleetlink.robots``,
key = robot); the uplink never produces that value as it came: it decodes it, checks it against
the site and edge the batch arrived from and the robot's owner, and writes a value of its own
(``uplink.registration_records``).
"""

from __future__ import annotations

from typing import Any

SITE_HEADER = "fleetlink.site"
"""The site a record came from (set by the edge, checked by the uplink against the batch's key)."""
EDGE_HEADER = "fleetlink.edge"
"""The edge agent a record came from (checked like ``fleetlink.site``)."""
ROBOT_HEADER = "fleetlink.robot"
IDENTITY_HEADERS: frozenset[str] = frozenset((SITE_HEADER, EDGE_HEADER))
"""Headers that say who sent a record: the uplink refuses a batch whose records name another sender."""

EVENT_KINDS: tuple[str, ...] = ("registered", "deregistered")
EVENT_SCHEMA: dict[str, Any] = {
    "type": "record",
    "name": "RobotEvent",
    "namespace": "fleetlink",
    "doc": "A robot registered at, or deregistered from, a fleetlink edge.",
    "fields": [
        {"name": "robot", "type": "string"},
        {"name": "robot_type", "type": "string"},
        {"name": "site", "type": "string"},
        {"name": "edge_id", "type": "string"},
        {
            "name": "event",
            "type": {"type": "enum", "name": "RobotEventKind", "symbols": list(EVENT_KINDS)},
        },
        {"name": "reason", "type": "string", "doc": "discovered | explicit | liveliness_lost | config"},
        {"name": "timestamp", "type": {"type": "long", "logicalType": "timestamp-millis"}},
    ],
}
