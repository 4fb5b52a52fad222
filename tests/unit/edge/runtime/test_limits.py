"""The uplink's record limit as the edge learns and keeps it."""

from __future__ import annotations

from pathlib import Path

from fleetlink.edge.runtime.limits import FILE_NAME, RecordLimit
from fleetlink.wire.limits import DEFAULT_MAX_RECORD_BYTES


def test_default_until_an_uplink_speaks_then_what_it_said_kept_across_restarts(tmp_path: Path) -> None:
    heard: list[int] = []
    limit = RecordLimit(None, tmp_path).load()
    limit.on_change(heard.append)
    assert limit.value == DEFAULT_MAX_RECORD_BYTES
    limit.learn(0)  # an uplink that says nothing changes nothing
    limit.learn(200_000)
    limit.learn(200_000)
    assert (limit.value, limit.learned) == (200_000, 200_000)
    assert heard == [DEFAULT_MAX_RECORD_BYTES, 200_000]
    again = RecordLimit(None, tmp_path).load()
    assert again.value == 200_000


def test_a_configured_limit_caps_what_is_learned(tmp_path: Path) -> None:
    limit = RecordLimit(500_000, tmp_path).load()
    assert limit.value == 500_000
    limit.learn(2_000_000)
    assert limit.value == 500_000
    limit.learn(100_000)
    assert limit.value == 100_000


def test_an_unreadable_file_is_ignored(tmp_path: Path) -> None:
    (tmp_path / FILE_NAME).write_text("{not json")
    assert RecordLimit(None, tmp_path).load().value == DEFAULT_MAX_RECORD_BYTES
