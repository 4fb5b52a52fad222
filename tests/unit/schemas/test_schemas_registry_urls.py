"""Which URL of an Apicurio Registry each client takes."""

from __future__ import annotations

import pytest

from fleetlink.schemas.registry_urls import APICURIO_CCOMPAT_PATH, APICURIO_NATIVE_PATH, apicurio_native_url


@pytest.mark.parametrize(
    ("url", "native"),
    [
        ("http://127.0.0.1:8081/apis/ccompat/v7", "http://127.0.0.1:8081/apis/registry/v3"),
        ("http://127.0.0.1:8081/apis/ccompat/v7/", "http://127.0.0.1:8081/apis/registry/v3"),
        ("https://reg.example:443/apis/ccompat/v6", "https://reg.example:443/apis/registry/v3"),
        ("http://h:1/prefix/apis/ccompat/v7", "http://h:1/prefix/apis/registry/v3"),
        ("http://confluent:8081", None),  # another registry: no native Apicurio API
        ("http://h:1/apis/registry/v3", None),
        ("/apis/ccompat/v7", None),
    ],
)
def test_the_native_api_sits_beside_the_confluent_compatible_one(url: str, native: str | None) -> None:
    assert apicurio_native_url(url) == native


def test_the_paths_are_apicurio_3s() -> None:
    assert APICURIO_CCOMPAT_PATH == "/apis/ccompat/v7"
    assert APICURIO_NATIVE_PATH == "/apis/registry/v3"
