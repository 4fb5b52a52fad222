"""AWS Signature Version 4 for S3 requests (header-based; pure: the time is passed in).

The four steps of the AWS documentation ("Authenticating Requests: Using the Authorization
Header"): a canonical request (method, URI, query, the signed headers, the payload's SHA-256),
the string to sign (algorithm, time, scope, the canonical request's SHA-256), the signing key
(HMAC-SHA256 chain over date, region, service, ``aws4_request``) and the signature. S3 URIs are
encoded once (``/`` kept), unlike the other services' double encoding.
"""

from __future__ import annotations

import hashlib
import hmac
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from urllib.parse import quote

ALGORITHM = "AWS4-HMAC-SHA256"
EMPTY_SHA256 = hashlib.sha256(b"").hexdigest()
_UNRESERVED = "-._~"


@dataclass(frozen=True, slots=True)
class Credentials:
    """An S3 access key pair and the region and service requests are signed for."""

    access_key_id: str
    secret_access_key: str
    region: str = "us-east-1"
    service: str = "s3"


def amz_date(when: datetime) -> str:
    """``20130524T000000Z``."""
    return when.astimezone(UTC).strftime("%Y%m%dT%H%M%SZ")


def uri_encode(text: str, *, keep_slash: bool) -> str:
    """RFC 3986 percent-encoding of everything but unreserved characters (and ``/`` in paths)."""
    return quote(text, safe=_UNRESERVED + ("/" if keep_slash else ""))


@dataclass(frozen=True, slots=True)
class Request:
    """What is signed of a request: ``headers`` must hold ``host``, ``x-amz-date`` and
    ``x-amz-content-sha256`` (``payload_sha256``); every one of them is signed."""

    method: str
    path: str
    headers: Mapping[str, str]
    payload_sha256: str
    query: Mapping[str, str] = field(default_factory=dict)


def canonical_query(query: Mapping[str, str]) -> str:
    """The query string of the canonical request: keys and values encoded, pairs sorted."""
    pairs = sorted(
        (uri_encode(k, keep_slash=False), uri_encode(v, keep_slash=False)) for k, v in query.items()
    )
    return "&".join(f"{k}={v}" for k, v in pairs)


def canonical_request(request: Request) -> tuple[str, str]:
    """(the canonical request, its signed-headers list)."""
    lowered = sorted(
        (name.lower(), " ".join(value.strip().split())) for name, value in request.headers.items()
    )
    signed = ";".join(name for name, _value in lowered)
    lines = [
        request.method.upper(),
        uri_encode(request.path or "/", keep_slash=True),
        canonical_query(request.query),
        *(f"{name}:{value}" for name, value in lowered),
        "",
        signed,
        request.payload_sha256,
    ]
    return "\n".join(lines), signed


def scope(when: datetime, creds: Credentials) -> str:
    """The credential scope: ``<yyyymmdd>/<region>/<service>/aws4_request``."""
    return f"{amz_date(when)[:8]}/{creds.region}/{creds.service}/aws4_request"


def string_to_sign(when: datetime, creds: Credentials, canonical: str) -> str:
    """The string to sign: algorithm, time, scope and the SHA-256 of ``canonical``."""
    digest = hashlib.sha256(canonical.encode("utf-8")).hexdigest()
    return "\n".join((ALGORITHM, amz_date(when), scope(when, creds), digest))


def signing_key(when: datetime, creds: Credentials) -> bytes:
    """The signing key: an HMAC-SHA256 chain from the secret over date, region, service, ``aws4_request``."""
    key = ("AWS4" + creds.secret_access_key).encode("utf-8")
    for part in (amz_date(when)[:8], creds.region, creds.service, "aws4_request"):
        key = hmac.new(key, part.encode("utf-8"), hashlib.sha256).digest()
    return key


def authorization(request: Request, creds: Credentials, when: datetime) -> str:
    """The ``Authorization`` header of ``request``."""
    canonical, signed = canonical_request(request)
    to_sign = string_to_sign(when, creds, canonical).encode("utf-8")
    signature = hmac.new(signing_key(when, creds), to_sign, hashlib.sha256).hexdigest()
    credential = f"{creds.access_key_id}/{scope(when, creds)}"
    return f"{ALGORITHM} Credential={credential},SignedHeaders={signed},Signature={signature}"


def signed_headers(
    method: str,
    path: str,
    *,
    host: str,
    payload_sha256: str,
    creds: Credentials,
    when: datetime,
    extra: Mapping[str, str] | None = None,
) -> dict[str, str]:
    """Every header a request (no query) needs to be accepted: ``host``, ``x-amz-date``,
    ``x-amz-content-sha256``, ``extra`` (signed too) and ``Authorization``."""
    headers = {
        "host": host,
        "x-amz-date": amz_date(when),
        "x-amz-content-sha256": payload_sha256,
        **(extra or {}),
    }
    headers["Authorization"] = authorization(Request(method, path, headers, payload_sha256), creds, when)
    return headers
