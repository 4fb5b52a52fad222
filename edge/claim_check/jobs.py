"""What the record maker hands the uploader, and what comes back (pure data)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True, slots=True)
class Upload:
    """One object to put."""

    key: str
    data: bytes
    sha256: str
    content_type: str


@dataclass(frozen=True, slots=True)
class ObjectRef:
    """Where an uploaded payload is (the ``fleetlink.ObjectRef`` record)."""

    url: str
    bucket: str
    key: str
    size: int
    sha256: str
    content_type: str

    def as_datum(self) -> dict[str, Any]:
        """The reference as an Avro datum of the ``fleetlink.ObjectRef`` record."""
        return {
            "url": self.url,
            "bucket": self.bucket,
            "key": self.key,
            "size": self.size,
            "sha256": self.sha256,
            "content_type": self.content_type,
        }


@dataclass(frozen=True, slots=True)
class ClaimJob:
    """A record of a claim-checking mapping on its way to the spool. ``lane`` keeps order: the
    jobs of one lane (a robot's records of one mapping) finish in the order they were made, so
    a small record never overtakes a large one of the same robot. ``upload`` is None for a record
    whose payload stays inline (it only waits its turn); ``context`` is the record maker's."""

    lane: str
    upload: Upload | None
    context: Any
    size: int
    """Bytes the job holds while it waits (its payload), for the uploader's bound."""


@dataclass(frozen=True, slots=True)
class Claimed:
    """A finished job: ``ref`` when its object is stored, ``error`` when it will not be."""

    job: ClaimJob
    ref: ObjectRef | None = None
    error: str | None = None
