"""Who sent a batch: the site and edge of the key it arrived on, never what the batch says.

Edges send batches as queries on ``fleetlink/<site>/ingest/<edge_id>``. The cloud router's ACL
lets a link whose client certificate is ``edge-<site>`` query ``fleetlink/<site>/**`` only
(``common.zenoh_configs.cloud_site_acl``), so the key names the site the certificate proved. A
batch whose body names another site or edge, or whose records carry ``fleetlink.site`` /
``fleetlink.edge`` headers naming another sender, is refused as a whole: an honest edge never
writes one (pure: no I/O).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from fleetlink.common.names import key_chunk_problem
from fleetlink.wire import ROOT, Batch, Record
from fleetlink.wire.keys import VIA
from fleetlink.wire.robot_events import EDGE_HEADER, IDENTITY_HEADERS, SITE_HEADER


@dataclass(frozen=True, slots=True)
class Source:
    """The sender of a batch, as its key proves it."""

    site: str
    edge_id: str

    def __str__(self) -> str:
        return f"{self.site}/{self.edge_id}"


def source_of(key: str) -> Source | None:
    """The sender named by an ingest key ``fleetlink/<site>/ingest/<edge_id>``, or one addressed
    to an uplink (``.../via/<uplink id>``) (None: not one)."""
    parts = key.split("/")
    if len(parts) == 6 and parts[4] == VIA and key_chunk_problem(parts[5]) is None:
        parts = parts[:4]
    if len(parts) != 4 or parts[0] != ROOT or parts[2] != "ingest":
        return None
    site, edge_id = parts[1], parts[3]
    if key_chunk_problem(site) is not None or key_chunk_problem(edge_id) is not None:
        return None
    return Source(site, edge_id)


def identity_problem(source: Source, batch: Batch) -> str | None:
    """Why the batch's own site and edge id disagree with where it came from (None: they agree)."""
    if batch.site != source.site:
        return f"the batch says site {batch.site!r} but arrived on site {source.site!r}'s key"
    if batch.edge_id != source.edge_id:
        return f"the batch says edge {batch.edge_id!r} but arrived on edge {source.edge_id!r}'s key"
    return None


def header_problem(source: Source, records: Iterable[Record]) -> str | None:
    """Why a record's sender headers name someone else (None: every one names ``source``).

    One pass over the records' headers (the batch's checks cost about 0.25 us a record in all);
    no header is copied.
    """
    allowed = frozenset(((SITE_HEADER, source.site.encode()), (EDGE_HEADER, source.edge_id.encode())))
    names = IDENTITY_HEADERS
    for record in records:
        for header in record.headers:
            if header[0] in names and header not in allowed:
                value = header[1][:100].decode("utf-8", "replace")
                return (
                    f"record {record.seq} has header {header[0]}={value!r}, but the batch came from {source}"
                )
    return None
