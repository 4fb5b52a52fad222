"""The two APIs of an Apicurio Registry, and which client takes which (pure, no imports).

Confluent clients (fleetlink, confluent-kafka, Quix Streams, ``fleetlink kafka``) take the
Confluent-compatible API, ``http://HOST:PORT/apis/ccompat/v7``. Apicurio's own serdes (Java, 3.x)
take the registry's native API, ``http://HOST:PORT/apis/registry/v3``, and answer the ccompat
URL with a bare 404. Both name the same schemas; the ids ccompat hands out are Apicurio's
content ids.
"""

from __future__ import annotations

APICURIO_CCOMPAT_PATH = "/apis/ccompat/v7"
APICURIO_NATIVE_PATH = "/apis/registry/v3"


def apicurio_native_url(url: str) -> str | None:
    """The native API beside the Confluent-compatible ``url``; None when ``url`` is not Apicurio's ccompat."""
    base, sep, _ = url.rstrip("/").partition("/apis/ccompat/")
    if not sep or not base:
        return None
    return base + APICURIO_NATIVE_PATH
