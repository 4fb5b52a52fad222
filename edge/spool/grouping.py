"""Records into groups within the limits of one group (pure)."""

from __future__ import annotations

from collections.abc import Sequence

from fleetlink.wire.groups import encode_group


def pack_groups(payloads: Sequence[bytes], max_records: int, max_bytes: int) -> list[tuple[bytes, int]]:
    """``(group, count)`` of consecutive ``payloads``: at most ``max_records`` records and, beyond
    one record, ``max_bytes`` of payload each."""
    out: list[tuple[bytes, int]] = []
    start, size = 0, 0
    for i, payload in enumerate(payloads):
        if i > start and (i - start >= max_records or size + len(payload) > max_bytes):
            out.append((encode_group(payloads[start:i]), i - start))
            start, size = i, 0
        size += len(payload)
    if start < len(payloads):
        out.append((encode_group(payloads[start:]), len(payloads) - start))
    return out
