"""Entity GIDs: XXH3-128 of the token key, low 64 bits LE then high 64 bits LE."""

from __future__ import annotations

import pytest
import xxhash

from fleetlink.roswire.gid import entity_gid

KEYS = [
    "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener",
    "@ros2_lv/0/1/0/10/MP/%/%tb4_01/sim/%tb4_01%odom/nav_msgs::msg::dds_::Odometry_/TypeHashNotSupported/::,10:,:,:,,",
    "",
]


@pytest.mark.parametrize("key", KEYS)
def test_gid_is_low_then_high_little_endian(key: str) -> None:
    gid = entity_gid(key)
    digest = xxhash.xxh3_128(key.encode()).digest()  # big-endian: high64 then low64
    high, low = digest[:8], digest[8:]
    assert gid == low[::-1] + high[::-1]
    assert len(gid) == 16


def test_gid_pinned_vector() -> None:
    # XXH3-128("") with seed 0 is 99aa06d3014798d86001c324468d497f (canonical big-endian).
    assert entity_gid("") == bytes.fromhex("99aa06d3014798d86001c324468d497f")[::-1]


def test_distinct_keys_distinct_gids() -> None:
    assert len({entity_gid(k) for k in KEYS}) == len(KEYS)
