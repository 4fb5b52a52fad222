"""A small S3 client: put, get and head objects, make sure the bucket exists (path-style, SigV4)."""

from __future__ import annotations

import hashlib
import re
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from urllib.parse import urlsplit

import httpx

from fleetlink.common.objects.config import ObjectStoreSection
from fleetlink.common.objects.errors import ObjectStoreError
from fleetlink.common.objects.sigv4 import EMPTY_SHA256, Credentials, signed_headers, uri_encode

_RETRIABLE_STATUS = {408, 429, 500, 502, 503, 504}
_XML_FIELD = re.compile(r"<(Code|Message)>([^<]*)</\1>")


@dataclass(frozen=True, slots=True)
class ObjectInfo:
    """A stored object's key, size in bytes, content type and ETag (empty when the store sent none)."""

    key: str
    size: int
    content_type: str
    etag: str = ""


def _now() -> datetime:
    return datetime.now(UTC)


class ObjectStore:
    """One bucket of an S3-compatible store. Thread-safe (one ``httpx.Client``, which is)."""

    def __init__(self, section: ObjectStoreSection, *, clock: Callable[[], datetime] = _now) -> None:
        self.section = section
        self.bucket = section.bucket
        secret = section.resolve_secret()
        self._creds = (
            Credentials(section.access_key_id, secret, section.region)
            if section.access_key_id is not None and secret is not None
            else None
        )
        self._host = urlsplit(section.endpoint).netloc
        self._clock = clock
        self._client = httpx.Client(timeout=section.request_timeout, follow_redirects=False)

    def close(self) -> None:
        """Close the HTTP client and its connections."""
        self._client.close()

    def __enter__(self) -> ObjectStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- names -----------------------------------------------------------------------------------
    def path_of(self, key: str) -> str:
        """The request path of ``key`` in the bucket (the bucket itself for an empty key)."""
        return f"/{self.bucket}/{key}" if key else f"/{self.bucket}"

    def url_of(self, key: str) -> str:
        """Where ``key`` is read: ``<public_url>/<key>``, else ``<endpoint>/<bucket>/<key>``."""
        encoded = uri_encode(key, keep_slash=True)
        if self.section.public_url is not None:
            return f"{self.section.public_url}/{encoded}"
        return f"{self.section.endpoint}/{self.bucket}/{encoded}"

    # -- calls -----------------------------------------------------------------------------------
    def put(self, key: str, data: bytes, *, content_type: str, sha256_hex: str | None = None) -> ObjectInfo:
        """Store ``data`` under ``key`` (the same key and bytes again: the same object)."""
        digest = sha256_hex or hashlib.sha256(data).hexdigest()
        response = self._request(
            "PUT", self.path_of(key), body=data, payload_sha256=digest, extra={"content-type": content_type}
        )
        return ObjectInfo(key, len(data), content_type, response.headers.get("etag", "").strip('"'))

    def get(self, key: str) -> tuple[bytes, str]:
        """(the object's bytes, its content type)."""
        response = self._request("GET", self.path_of(key))
        return response.content, response.headers.get("content-type", "application/octet-stream")

    def head(self, key: str) -> ObjectInfo | None:
        """The object's size and type, or None when there is no such object."""
        response = self._request("HEAD", self.path_of(key), missing_ok=True)
        if response.status_code == 404:
            return None
        return ObjectInfo(
            key,
            int(response.headers.get("content-length", "0")),
            response.headers.get("content-type", "application/octet-stream"),
            response.headers.get("etag", "").strip('"'),
        )

    def ensure_bucket(self) -> bool:
        """Create the bucket unless it exists; True when it was created."""
        response = self._request("HEAD", self.path_of(""), missing_ok=True)
        if response.status_code != 404:
            return False
        self._request("PUT", self.path_of(""))
        return True

    def check(self) -> None:
        """Raise ``ObjectStoreError`` unless the bucket is there and the credentials are taken."""
        response = self._request("HEAD", self.path_of(""), missing_ok=True)
        if response.status_code == 404:
            raise ObjectStoreError(
                f"object store {self.section.endpoint}: bucket {self.bucket!r} does not exist",
                retriable=False,
                status=404,
            )

    # -- one request -----------------------------------------------------------------------------
    def _request(
        self,
        method: str,
        path: str,
        *,
        body: bytes = b"",
        payload_sha256: str | None = None,
        extra: dict[str, str] | None = None,
        missing_ok: bool = False,
    ) -> httpx.Response:
        digest = payload_sha256 or (EMPTY_SHA256 if not body else hashlib.sha256(body).hexdigest())
        encoded = uri_encode(path, keep_slash=True)
        if self._creds is not None:
            headers = signed_headers(
                method,
                path,
                host=self._host,
                payload_sha256=digest,
                creds=self._creds,
                when=self._clock(),
                extra=extra,
            )
        else:
            headers = dict(extra or {})
        what = f"{method} {self.section.endpoint}{encoded}"
        try:
            response = self._client.request(
                method, f"{self.section.endpoint}{encoded}", content=body or None, headers=headers
            )
        except httpx.TimeoutException:
            raise ObjectStoreError(
                f"{what}: no answer within {self.section.request_timeout:g} s", retriable=True
            ) from None
        except httpx.TransportError as exc:
            raise ObjectStoreError(f"{what}: {type(exc).__name__}: {exc}", retriable=True) from None
        status = response.status_code
        if status < 300 or (missing_ok and status == 404):
            return response
        raise ObjectStoreError(
            f"{what}: HTTP {status}{_reason(response)}", retriable=status in _RETRIABLE_STATUS, status=status
        )


def _reason(response: httpx.Response) -> str:
    """`` (Code: Message)`` from an S3 error document, when there is one."""
    found = dict(_XML_FIELD.findall(response.text[:4000])) if response.content else {}
    if not found:
        return ""
    return " (" + ": ".join(v for v in (found.get("Code"), found.get("Message")) if v) + ")"
