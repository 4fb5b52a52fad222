"""Schema ids per (topic, fingerprint): registered once, texts remembered across batches."""

from __future__ import annotations

from typing import Any

import pytest

from fleetlink.uplink.schema_ids import SchemaIds, SchemaRefusedError

FP_A, FP_B, FP_C = b"a" * 8, b"b" * 8, b"c" * 8
TEXT = '{"type": "record", "name": "A", "fields": []}'


class Registry:
    def __init__(self) -> None:
        self.registered: list[str] = []

    def register(self, subject: str, schema: dict[str, Any]) -> int:
        self.registered.append(subject)
        return len(self.registered)

    def set_compatibility(self, subject: str, level: str) -> None:
        raise AssertionError("not configured")


def test_a_text_read_in_one_batch_serves_later_batches_and_other_topics() -> None:
    registry = Registry()
    ids = SchemaIds(registry)
    assert ids.unknown([FP_A, FP_B]) == (FP_A, FP_B)
    ids.learn({FP_A: TEXT})
    assert ids.unknown([FP_B, FP_A]) == (FP_B,)
    assert ids.id_for("t1", FP_A, {}) == 1
    assert ids.id_for("t1", FP_A, {}) == 1  # cached: registered once
    assert ids.id_for("t2", FP_A, {}) == 2
    assert registry.registered == ["t1-value", "t2-value"]
    with pytest.raises(SchemaRefusedError, match="no schema for fingerprint"):
        ids.id_for("t1", FP_B, {})


def test_the_oldest_texts_are_forgotten_past_the_limit() -> None:
    ids = SchemaIds(Registry(), max_texts=2)
    ids.learn({FP_A: TEXT})
    ids.learn({FP_B: TEXT, FP_C: TEXT})
    assert ids.unknown([FP_A, FP_B, FP_C]) == (FP_A,)
