"""Schema ids per (site, topic, fingerprint): texts verified against their fingerprint, kept per
site, registered once."""

from __future__ import annotations

import json
from typing import Any

import pytest

from fleetlink.schemas.single_object import fingerprint
from fleetlink.uplink.schema_ids import SchemaIds, SchemaRefusedError


def schema(name: str, doc: str = "") -> str:
    return json.dumps({"type": "record", "name": name, "doc": doc, "fields": [{"name": "x", "type": "long"}]})


TEXT_A, TEXT_B, TEXT_C = schema("A"), schema("B"), schema("C")
FP_A, FP_B, FP_C = fingerprint(TEXT_A), fingerprint(TEXT_B), fingerprint(TEXT_C)


class Registry:
    def __init__(self) -> None:
        self.registered: list[tuple[str, str]] = []

    def register(self, subject: str, schema: dict[str, Any]) -> int:
        self.registered.append((subject, schema.get("doc", "")))
        return len(self.registered)

    def set_compatibility(self, subject: str, level: str) -> None:
        raise AssertionError("not configured")


def test_a_text_read_in_one_batch_serves_later_batches_and_other_topics() -> None:
    registry = Registry()
    ids = SchemaIds(registry)
    assert ids.unknown("s", [FP_A, FP_B]) == tuple(sorted((FP_A, FP_B)))
    assert ids.learn("s", {FP_A: TEXT_A}) == []
    assert ids.unknown("s", [FP_B, FP_A]) == (FP_B,)
    assert ids.id_for("s", "t1", FP_A) == 1
    assert ids.id_for("s", "t1", FP_A) == 1  # cached: registered once
    assert ids.id_for("s", "t2", FP_A) == 2
    assert [subject for subject, _ in registry.registered] == ["t1-value", "t2-value"]
    with pytest.raises(SchemaRefusedError, match="no schema for fingerprint"):
        ids.id_for("s", "t1", FP_B)


def test_a_text_that_does_not_match_its_fingerprint_is_not_learnt() -> None:
    ids = SchemaIds(Registry())
    assert ids.learn("s", {FP_A: TEXT_B, FP_C: TEXT_C, FP_B: "not json"}) == [FP_A, FP_B]
    assert ids.unknown("s", [FP_A, FP_B, FP_C]) == tuple(sorted((FP_A, FP_B)))


def test_texts_are_kept_per_site_so_one_site_cannot_change_what_another_registers() -> None:
    registry = Registry()
    ids = SchemaIds(registry)
    poisoned = schema("A", doc="attacker")  # same canonical form, so the same fingerprint
    assert fingerprint(poisoned) == FP_A
    assert ids.learn("site-b", {FP_A: poisoned}) == []
    assert ids.unknown("site-a", [FP_A]) == (FP_A,)  # site A's left-out schema is not site B's
    assert ids.learn("site-a", {FP_A: TEXT_A}) == []
    ids.id_for("site-b", "fleet.x", FP_A)
    ids.id_for("site-a", "fleet.x", FP_A)
    assert registry.registered == [("fleet.x-value", "attacker"), ("fleet.x-value", "")]


def test_the_oldest_texts_are_forgotten_past_the_limit() -> None:
    ids = SchemaIds(Registry(), max_texts=2)
    ids.learn("s", {FP_A: TEXT_A})
    ids.learn("s", {FP_B: TEXT_B, FP_C: TEXT_C})
    assert ids.unknown("s", [FP_A, FP_B, FP_C]) == (FP_A,)


def test_a_wrong_text_for_a_known_fingerprint_is_refused_too() -> None:
    ids = SchemaIds(Registry())
    assert ids.learn("s", {FP_A: TEXT_A}) == []
    assert ids.learn("s", {FP_A: TEXT_B}) == [FP_A]
    assert ids.learn("s", {FP_A: schema("A", doc="other doc")}) == []  # matches: the first one stays
    assert ids.id_for("s", "t", FP_A) == 1
