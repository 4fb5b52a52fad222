"""A mapping's ``claim_check:`` section."""

from __future__ import annotations

from pydantic import ByteSize, Field

from fleetlink.common.configfile import Section
from fleetlink.common.names import KeyChunk


class ClaimCheckSpec(Section):
    """Payloads above ``above`` bytes go to the edge's object store (``objects:``); the record
    carries their URL, size, SHA-256 and content type instead (docs/images.md)."""

    above: ByteSize = Field(
        default=ByteSize(256 << 10),
        description="a payload larger than this goes to the object store (0: every payload); so "
        "does any payload whose record would pass the uplink's Kafka limit",
    )
    field: KeyChunk = Field(
        default="data",
        description="the message's top-level bytes field (uint8[]) that holds the payload",
    )
