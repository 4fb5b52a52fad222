"""Entity GIDs as rmw_zenoh computes them: XXH3-128 of the liveliness token key (rmw_zenoh.md §3).

The 16 bytes are the low 64 bits little-endian followed by the high 64 bits little-endian,
which is the 128-bit digest as one little-endian integer.
"""

from __future__ import annotations

import xxhash

GID_SIZE = 16


def entity_gid(token_key: str) -> bytes:
    """The 16-byte GID of the entity that declared ``token_key``."""
    digest: int = xxhash.xxh3_128_intdigest(token_key.encode("utf-8"))
    return digest.to_bytes(GID_SIZE, "little")
