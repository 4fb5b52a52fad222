"""The console's status book: a status record sent again is shown once."""

from __future__ import annotations

import json
from typing import Any

from fleetlink.console.kafka_ops import StatusBook
from fleetlink.console.kafka_tail import TailRecord


def record(offset: int, **datum: Any) -> TailRecord:
    return TailRecord(0, offset, 1_000 + offset, None, json.dumps(datum).encode(), ())


def test_a_status_record_sent_again_is_kept_once() -> None:
    book = StatusBook(json.loads)
    for offset, (status, site) in enumerate(
        [("accepted", "a"), ("accepted", "a"), ("accepted", "b"), ("succeeded", "a"), ("succeeded", "a")]
    ):
        book.on_record(record(offset, command_id="c1", status=status, site=site, robot="tb4_01", at=offset))
    entries = book.of(["c1", "unknown"])
    assert [(e["status"], e["site"]) for e in entries["c1"]] == [
        ("accepted", "a"),
        ("accepted", "b"),  # another site's report is another status
        ("succeeded", "a"),
    ]
    assert entries["unknown"] == []
