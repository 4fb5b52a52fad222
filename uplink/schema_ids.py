"""Schema ids for (site, topic, fingerprint): registered once under ``<topic>-value``, then cached.

The edge names each value's schema by its 64-bit fingerprint and ships the schema text in the
batch until an uplink has acknowledged it; the uplink keeps every text it read (``learn``),
registers it under the record's topic subject (TopicNameStrategy) and reuses the id for every
later record of that triple. ``unknown`` names the left-out schemas it has no text for: the
batch is then answered ``need_schemas`` before anything is produced. A registry that cannot be
reached is retriable (the batch goes back to the edge's spool); a registry that refuses the
schema is not (the records go to the dead-letter topic with the registry's reason).

Texts are verified and kept per site: ``learn`` computes the fingerprint of every text it has
not seen from that site and returns those that do not match the fingerprint they came with
(the batch is then refused), and a site's records only ever use texts that site sent. A text
with the right fingerprint may still differ in what the fingerprint leaves out (docs, defaults,
logical types); kept per site, it can only describe that site's own records.
"""

from __future__ import annotations

import json
import threading
from collections import Counter
from collections.abc import Iterable, Mapping
from typing import Any, Protocol

from fleetlink.schemas.errors import IncompatibleSchemaError, RegistryError
from fleetlink.schemas.registry import RegistryUnavailableError, subject_for_topic
from fleetlink.schemas.single_object import fingerprint


class Registry(Protocol):
    """The schema registry calls ``SchemaIds`` makes."""

    def register(self, subject: str, schema: dict[str, Any]) -> int:
        """Register ``schema`` under ``subject`` (or find it there); returns the schema id."""

    def set_compatibility(self, subject: str, level: str) -> None:
        """Set the compatibility level (``BACKWARD``, ``FULL``, ``NONE`` ...) of ``subject``."""


class SchemaRefusedError(Exception):
    """The registry refused the schema: the records cannot be produced under it."""


class SchemaUnavailableError(Exception):
    """The registry could not answer now: try again later."""


MAX_TEXTS = 10_000
"""Schema texts kept (a fleet uses a few hundred at most); past this the oldest are forgotten,
and an edge that left one out is asked for it again."""


class SchemaIds:
    """The schema texts each site sent, verified against their fingerprints, and their registry ids per
    topic, cached."""

    def __init__(
        self, registry: Registry, *, compatibility: str | None = None, max_texts: int = MAX_TEXTS
    ) -> None:
        self._registry = registry
        self._compatibility = compatibility
        self._ids: dict[tuple[str, str, bytes], int] = {}
        self._texts: dict[tuple[str, bytes], str] = {}
        self._max_texts = max_texts
        self._lock = threading.Lock()
        self.errors: Counter[str] = Counter()

    def learn(self, site: str, schemas: Mapping[bytes, str]) -> list[bytes]:
        """Remember the schema texts a batch from ``site`` carried (by fingerprint); a text not
        seen before from that site is checked against its fingerprint first. Returns the
        fingerprints whose text does not match (none of those is learnt). The first matching text
        of a fingerprint stays (another matching one differs only in docs or defaults)."""
        texts = self._texts
        if all(texts.get((site, fp)) == text for fp, text in schemas.items()):
            return []
        wrong: list[bytes] = []
        for fp, text in schemas.items():
            known = texts.get((site, fp))
            if known == text:
                continue
            if not _matches(fp, text):
                wrong.append(fp)
                continue
            if known is None:
                with self._lock:
                    if len(texts) >= self._max_texts:
                        del texts[next(iter(texts))]
                    texts[site, fp] = text
        return wrong

    def unknown(self, site: str, fingerprints: Iterable[bytes]) -> tuple[bytes, ...]:
        """Those of ``fingerprints`` with no text known here from ``site``, in a stable order."""
        return tuple(sorted(fp for fp in fingerprints if (site, fp) not in self._texts))

    def _failed(self, reason: str) -> None:
        with self._lock:
            self.errors[reason] += 1

    def error_totals(self) -> dict[str, int]:
        """Registry requests that failed, by reason (``unavailable``, ``incompatible``, ``refused``)."""
        with self._lock:
            return dict(self.errors)

    def id_for(
        self, site: str, topic: str, fingerprint: bytes, schemas: Mapping[bytes, str] | None = None
    ) -> int:
        """The registry id of ``site``'s schema ``fingerprint`` under ``topic``'s subject;
        ``schemas``: the texts of the batch at hand, which ``learn`` verified."""
        key = (site, topic, fingerprint)
        cached = self._ids.get(key)
        if cached is not None:
            return cached
        text = schemas.get(fingerprint) if schemas else None
        if text is None:
            text = self._texts.get((site, fingerprint))
        if text is None:
            raise SchemaRefusedError(f"the batch carries no schema for fingerprint {fingerprint.hex()}")
        subject = subject_for_topic(topic)
        try:
            schema = json.loads(text)
            if self._compatibility is not None:
                self._registry.set_compatibility(subject, self._compatibility)
            schema_id = self._registry.register(subject, schema)
        except json.JSONDecodeError as exc:
            raise SchemaRefusedError(f"schema for {fingerprint.hex()} is not JSON: {exc}") from None
        except RegistryUnavailableError as exc:
            self._failed("unavailable")
            raise SchemaUnavailableError(str(exc)) from None
        except IncompatibleSchemaError as exc:
            self._failed("incompatible")
            raise SchemaRefusedError(str(exc)) from None
        except RegistryError as exc:
            self._failed("refused")
            raise SchemaRefusedError(str(exc)) from None
        with self._lock:
            self._ids[key] = schema_id
        return schema_id


def _matches(expected: bytes, text: str) -> bool:
    """Is ``text`` an Avro schema whose fingerprint is ``expected``?"""
    try:
        return fingerprint(text) == expected
    except Exception:  # noqa: BLE001 - not JSON, not a schema fastavro can put in canonical form
        return False
