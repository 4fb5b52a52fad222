"""Schema registry client side: register under ``<topic>-value``, cache ids, check compatibility.

A thin adapter over ``confluent_kafka.schema_registry.SchemaRegistryClient`` talking to any
Confluent-compatible registry (Apicurio Registry 3 under ``/apis/ccompat/v7`` here). Nothing
touches the network before the first call (or :meth:`SchemaRegistry.start`); use it as a context
manager to close its connections.

Refusals carry the registry's own words: an incompatible schema raises
:class:`~schemas.errors.IncompatibleSchemaError` with the subject, the version it conflicts
with and the registry's message. Apicurio's compatibility endpoint answers only
``is_compatible``; its reasons come with the refused registration, so :meth:`check_compatible`
asks for them that way (a registration the registry refuses changes nothing).
"""

from __future__ import annotations

import hashlib
import json
import threading
from collections.abc import Callable
from typing import Any, TypeVar
from urllib.parse import quote

import httpx
from confluent_kafka.schema_registry import Schema, SchemaRegistryClient
from confluent_kafka.schema_registry.error import SchemaRegistryError

from fleetlink.common.lifecycle import StartStop
from fleetlink.schemas.errors import IncompatibleSchemaError, RegistryError
from fleetlink.schemas.single_object import fingerprint

_CONFLICT = 409
_NOT_FOUND = 404
_SERVER_ERROR = 500
_CONTENT_TYPE = "application/vnd.schemaregistry.v1+json"
_ATTEMPTS = 3
# the connection under a request failed (not a timeout, not an HTTP answer): a new one may not
_CONNECTION_ERRORS = (httpx.NetworkError, httpx.RemoteProtocolError, OSError)

T = TypeVar("T")


class RegistryUnavailableError(RegistryError):
    """The registry could not be reached or failed (5xx): retry later."""


def subject_for_topic(topic: str) -> str:
    """TopicNameStrategy: the value schema of ``topic`` lives under ``<topic>-value``."""
    return f"{topic}-value"


def on_a_live_connection(call: Callable[[], T], attempts: int = _ATTEMPTS) -> T:
    """``call()``, made again at once (up to ``attempts`` in all) when the connection under it
    failed. The HTTP client reuses kept-alive connections, and one may die under a request: the
    registry closed it, or the pool closed it while another thread had it (``[Errno 9] Bad file
    descriptor``, a reset). The next try opens a new one. Timeouts and the registry's answers
    are not tried again; every call made through here is idempotent at the registry."""
    for _ in range(attempts - 1):
        try:
            return call()
        except TimeoutError:
            raise
        except _CONNECTION_ERRORS:
            continue
    return call()


class SchemaRegistry(StartStop):
    """Register, look up and check Avro schemas; ids are cached per (subject, schema)."""

    def __init__(self, url: str, *, timeout: float = 10.0) -> None:
        self.url = url.rstrip("/")
        self.timeout = timeout
        self._client: SchemaRegistryClient | None = None
        self._http: httpx.Client | None = None
        self._lock = threading.Lock()
        self._ids: dict[tuple[str, bytes, str], int] = {}
        self._schemas: dict[int, dict[str, Any]] = {}

    # --- lifecycle -------------------------------------------------------------------------
    def start(self) -> None:
        """Create the registry and HTTP clients (nothing is sent yet); a second call does nothing."""
        with self._lock:
            if self._client is None:
                self._client = SchemaRegistryClient({"url": self.url, "timeout": self.timeout})
                self._http = httpx.Client(base_url=self.url, timeout=self.timeout)

    def stop(self) -> None:
        """Close the registry and HTTP clients; a later call starts them again."""
        with self._lock:
            client, http = self._client, self._http
            self._client = self._http = None
        if client is not None:
            client.__exit__()
        if http is not None:
            http.close()

    def _sr(self) -> SchemaRegistryClient:
        if self._client is None:
            self.start()
        client = self._client
        if client is None:
            raise RegistryError("-", "client stopped")
        return client

    # --- operations ------------------------------------------------------------------------
    def register(self, subject: str, schema: dict[str, Any]) -> int:
        """Register ``schema`` under ``subject`` (or find it there); returns the schema id."""
        text = json.dumps(schema)
        key = (subject, fingerprint(schema), hashlib.sha256(text.encode()).hexdigest())
        with self._lock:
            cached = self._ids.get(key)
        if cached is not None:
            return cached
        try:
            schema_id: int = on_a_live_connection(
                lambda: self._sr().register_schema(subject, Schema(text, "AVRO"))
            )
        except SchemaRegistryError as exc:
            if exc.http_status_code == _CONFLICT:
                raise IncompatibleSchemaError(
                    subject, self._latest_version(subject), exc.error_message
                ) from exc
            raise self._error(subject, exc) from exc
        except (httpx.HTTPError, OSError) as exc:
            raise RegistryUnavailableError(subject, f"cannot reach {self.url}: {exc}") from exc
        with self._lock:
            self._ids[key] = schema_id
            self._schemas.setdefault(schema_id, json.loads(text))
        return schema_id

    def check_compatible(self, subject: str, schema: dict[str, Any]) -> None:
        """Raise :class:`IncompatibleSchemaError` unless ``schema`` may be registered under ``subject``."""
        body = {"schema": json.dumps(schema), "schemaType": "AVRO"}
        path = f"/compatibility/subjects/{quote(subject, safe='')}/versions/latest"
        answer = self._post(subject, path, body, {"verbose": "true"})
        if answer is None or answer.get("is_compatible", False):
            return  # no version yet (404), or compatible
        version = self._latest_version(subject)
        messages = answer.get("messages") or []
        if messages:
            raise IncompatibleSchemaError(subject, version, "; ".join(str(m) for m in messages))
        # The registry gave no reasons: its refusal of the registration states them.
        try:
            on_a_live_connection(lambda: self._sr().register_schema(subject, Schema(body["schema"], "AVRO")))
        except SchemaRegistryError as exc:
            raise IncompatibleSchemaError(subject, version, exc.error_message) from exc
        except (httpx.HTTPError, OSError) as exc:
            raise RegistryUnavailableError(subject, f"cannot reach {self.url}: {exc}") from exc
        raise IncompatibleSchemaError(subject, version, "registry reported is_compatible=false")

    def schema_by_id(self, schema_id: int) -> dict[str, Any]:
        """The schema registered with ``schema_id`` (cached)."""
        with self._lock:
            cached = self._schemas.get(schema_id)
        if cached is not None:
            return cached
        try:
            text = on_a_live_connection(lambda: self._sr().get_schema(schema_id)).schema_str
        except SchemaRegistryError as exc:
            raise self._error(f"id {schema_id}", exc) from exc
        except (httpx.HTTPError, OSError) as exc:
            raise RegistryUnavailableError(f"id {schema_id}", f"cannot reach {self.url}: {exc}") from exc
        schema: dict[str, Any] = json.loads(text)
        with self._lock:
            self._schemas[schema_id] = schema
        return schema

    def latest(self, subject: str) -> tuple[int, int, dict[str, Any]]:
        """(schema id, version, schema) of the newest version registered under ``subject``."""
        try:
            registered = on_a_live_connection(lambda: self._sr().get_latest_version(subject))
        except SchemaRegistryError as exc:
            if exc.http_status_code == _NOT_FOUND:
                raise RegistryError(subject, "no schema registered under this subject") from exc
            raise self._error(subject, exc) from exc
        except (httpx.HTTPError, OSError) as exc:
            raise RegistryUnavailableError(subject, f"cannot reach {self.url}: {exc}") from exc
        schema: dict[str, Any] = json.loads(registered.schema.schema_str)
        schema_id = int(registered.schema_id)
        with self._lock:
            self._schemas.setdefault(schema_id, schema)
        return schema_id, int(registered.version), schema

    def set_compatibility(self, subject: str, level: str) -> None:
        """Set the compatibility level (``BACKWARD``, ``FULL``, ``NONE`` ...) of ``subject``."""
        try:
            on_a_live_connection(lambda: self._sr().set_compatibility(subject, level))
        except SchemaRegistryError as exc:
            raise self._error(subject, exc) from exc
        except (httpx.HTTPError, OSError) as exc:
            raise RegistryUnavailableError(subject, f"cannot reach {self.url}: {exc}") from exc

    # --- helpers ---------------------------------------------------------------------------
    def _latest_version(self, subject: str) -> int | str:
        try:
            version = on_a_live_connection(lambda: self._sr().get_latest_version(subject)).version
        except (SchemaRegistryError, httpx.HTTPError, OSError):
            return "latest"
        return version if isinstance(version, int) else "latest"

    def _post(self, subject: str, path: str, body: dict[str, Any], params: dict[str, str]) -> Any:
        self._sr()
        http = self._http
        if http is None:
            raise RegistryError(subject, "client stopped")
        try:
            response = on_a_live_connection(
                lambda: http.post(path, json=body, params=params, headers={"Content-Type": _CONTENT_TYPE})
            )
        except httpx.HTTPError as exc:
            raise RegistryUnavailableError(subject, f"cannot reach {self.url}: {exc}") from exc
        if response.status_code == _NOT_FOUND:
            return None
        if response.status_code >= _SERVER_ERROR:
            raise RegistryUnavailableError(subject, f"HTTP {response.status_code}: {response.text[:500]}")
        if response.status_code >= 400:
            raise RegistryError(subject, f"HTTP {response.status_code}: {response.text[:500]}")
        return response.json()

    @staticmethod
    def _error(subject: str, exc: SchemaRegistryError) -> RegistryError:
        status = exc.http_status_code
        reason = f"HTTP {status} (error {exc.error_code}): {exc.error_message}"
        if status is None or status < 0 or status >= _SERVER_ERROR:
            return RegistryUnavailableError(subject, reason)
        return RegistryError(subject, reason)
