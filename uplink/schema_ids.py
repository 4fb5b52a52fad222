"""Schema ids for (topic, fingerprint): registered once under ``<topic>-value``, then cached.

The edge names each value's schema by its 64-bit fingerprint and ships the schema text in the
batch; the uplink registers it under the record's topic subject (TopicNameStrategy) and reuses
the id for every later record of that pair. A registry that cannot be reached is retriable
(the batch goes back to the edge's spool); a registry that refuses the schema is not (the
records go to the dead-letter topic with the registry's reason).
"""

from __future__ import annotations

import json
import threading
from collections.abc import Mapping
from typing import Any, Protocol

from schemas.errors import IncompatibleSchemaError, RegistryError
from schemas.registry import RegistryUnavailableError, subject_for_topic


class Registry(Protocol):
    def register(self, subject: str, schema: dict[str, Any]) -> int: ...

    def set_compatibility(self, subject: str, level: str) -> None: ...


class SchemaRefusedError(Exception):
    """The registry refused the schema: the records cannot be produced under it."""


class SchemaUnavailableError(Exception):
    """The registry could not answer now: try again later."""


class SchemaIds:
    def __init__(self, registry: Registry, *, compatibility: str | None = None) -> None:
        self._registry = registry
        self._compatibility = compatibility
        self._ids: dict[tuple[str, bytes], int] = {}
        self._lock = threading.Lock()

    def id_for(self, topic: str, fingerprint: bytes, schemas: Mapping[bytes, str]) -> int:
        key = (topic, fingerprint)
        cached = self._ids.get(key)
        if cached is not None:
            return cached
        text = schemas.get(fingerprint)
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
