"""Schema ids for (topic, fingerprint): registered once under ``<topic>-value``, then cached.

The edge names each value's schema by its 64-bit fingerprint and ships the schema text in the
batch until an uplink has acknowledged it; the uplink keeps every text it read (``learn``),
registers it under the record's topic subject (TopicNameStrategy) and reuses the id for every
later record of that pair. ``unknown`` names the left-out schemas it has no text for: the
batch is then answered ``need_schemas`` before anything is produced. A registry that cannot be
reached is retriable (the batch goes back to the edge's spool); a registry that refuses the
schema is not (the records go to the dead-letter topic with the registry's reason).
"""

from __future__ import annotations

import json
import threading
from collections.abc import Iterable, Mapping
from typing import Any, Protocol

from fleetlink.schemas.errors import IncompatibleSchemaError, RegistryError
from fleetlink.schemas.registry import RegistryUnavailableError, subject_for_topic


class Registry(Protocol):
    def register(self, subject: str, schema: dict[str, Any]) -> int: ...

    def set_compatibility(self, subject: str, level: str) -> None: ...


class SchemaRefusedError(Exception):
    """The registry refused the schema: the records cannot be produced under it."""


class SchemaUnavailableError(Exception):
    """The registry could not answer now: try again later."""


MAX_TEXTS = 10_000
"""Schema texts kept (a fleet uses a few hundred at most); past this the oldest are forgotten,
and an edge that left one out is asked for it again."""


class SchemaIds:
    def __init__(
        self, registry: Registry, *, compatibility: str | None = None, max_texts: int = MAX_TEXTS
    ) -> None:
        self._registry = registry
        self._compatibility = compatibility
        self._ids: dict[tuple[str, bytes], int] = {}
        self._texts: dict[bytes, str] = {}
        self._max_texts = max_texts
        self._lock = threading.Lock()

    def learn(self, schemas: Mapping[bytes, str]) -> None:
        """Remember the schema texts a batch carried (by fingerprint)."""
        texts = self._texts
        if all(fp in texts for fp in schemas):
            return
        with self._lock:
            for fp, text in schemas.items():
                if fp not in texts:
                    if len(texts) >= self._max_texts:
                        del texts[next(iter(texts))]
                    texts[fp] = text

    def unknown(self, fingerprints: Iterable[bytes]) -> tuple[bytes, ...]:
        """Those of ``fingerprints`` with no text known here, in a stable order."""
        return tuple(sorted(fp for fp in fingerprints if fp not in self._texts))

    def id_for(self, topic: str, fingerprint: bytes, schemas: Mapping[bytes, str]) -> int:
        key = (topic, fingerprint)
        cached = self._ids.get(key)
        if cached is not None:
            return cached
        text = schemas.get(fingerprint)
        if text is None:
            text = self._texts.get(fingerprint)
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
            raise SchemaUnavailableError(str(exc)) from None
        except IncompatibleSchemaError as exc:
            raise SchemaRefusedError(str(exc)) from None
        except RegistryError as exc:
            raise SchemaRefusedError(str(exc)) from None
        with self._lock:
            self._ids[key] = schema_id
        return schema_id
