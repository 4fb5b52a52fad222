"""The object store's pieces that need no server: SigV4 signatures, the config section, keys."""

from __future__ import annotations

import hashlib
import re
from datetime import UTC, datetime
from pathlib import Path

import pytest
from pydantic import ValidationError

from fleetlink.common.objects import ObjectStoreError, ObjectStoreSection
from fleetlink.common.objects.sigv4 import (
    EMPTY_SHA256,
    Credentials,
    Request,
    authorization,
    canonical_query,
    canonical_request,
    signed_headers,
    uri_encode,
)
from fleetlink.common.objects.store import ObjectStore

# the worked examples of the AWS documentation ("Signature Calculations for the Authorization
# Header: Transferring Payload in a Single Chunk"), with its example credentials
AWS = Credentials("AKIAIOSFODNN7EXAMPLE", "wJalrXUtnFEMI/K7MDENG/bPxRfiCYEXAMPLEKEY")
WHEN = datetime(2013, 5, 24, tzinfo=UTC)
HOST = "examplebucket.s3.amazonaws.com"


def test_get_object_example() -> None:
    request = Request(
        "GET",
        "/test.txt",
        {
            "host": HOST,
            "range": "bytes=0-9",
            "x-amz-content-sha256": EMPTY_SHA256,
            "x-amz-date": "20130524T000000Z",
        },
        EMPTY_SHA256,
    )
    canonical, signed = canonical_request(request)
    assert canonical.splitlines()[:3] == ["GET", "/test.txt", ""]
    assert signed == "host;range;x-amz-content-sha256;x-amz-date"
    assert authorization(request, AWS, WHEN) == (
        "AWS4-HMAC-SHA256 Credential=AKIAIOSFODNN7EXAMPLE/20130524/us-east-1/s3/aws4_request,"
        "SignedHeaders=host;range;x-amz-content-sha256;x-amz-date,"
        "Signature=f0e8bdb87c964420e857bd35b5d6ed310bd44f0170aba48dd91039c6036bdb41"
    )


def test_put_object_example() -> None:
    body = hashlib.sha256(b"Welcome to Amazon S3.").hexdigest()
    request = Request(
        "PUT",
        "/test$file.text",
        {
            "Host": HOST,
            "Date": "Fri, 24 May 2013 00:00:00 GMT",
            "x-amz-date": "20130524T000000Z",
            "x-amz-storage-class": "REDUCED_REDUNDANCY",
            "x-amz-content-sha256": body,
        },
        body,
    )
    canonical, _signed = canonical_request(request)
    assert canonical.splitlines()[1] == "/test%24file.text"
    assert authorization(request, AWS, WHEN).endswith(
        "Signature=98ad721746da40c64f1a55b78f14c238d841ea1380cd77a1b5971af0ece108bd"
    )


def test_a_changed_byte_changes_the_signature() -> None:
    base = signed_headers("PUT", "/b/k", host=HOST, payload_sha256=EMPTY_SHA256, creds=AWS, when=WHEN)
    other_key = signed_headers("PUT", "/b/l", host=HOST, payload_sha256=EMPTY_SHA256, creds=AWS, when=WHEN)
    other_body = signed_headers("PUT", "/b/k", host=HOST, payload_sha256="0" * 64, creds=AWS, when=WHEN)
    later = signed_headers(
        "PUT",
        "/b/k",
        host=HOST,
        payload_sha256=EMPTY_SHA256,
        creds=AWS,
        when=datetime(2013, 5, 25, tzinfo=UTC),
    )
    signatures = {h["Authorization"] for h in (base, other_key, other_body, later)}
    assert len(signatures) == 4
    assert base["x-amz-date"] == "20130524T000000Z"


def test_uri_and_query_encoding() -> None:
    assert uri_encode("a b/c~d", keep_slash=True) == "a%20b/c~d"
    assert uri_encode("a/b", keep_slash=False) == "a%2Fb"
    assert canonical_query({"prefix": "x/y", "delimiter": "/", "a": ""}) == "a=&delimiter=%2F&prefix=x%2Fy"


def _section(**data: object) -> ObjectStoreSection:
    return ObjectStoreSection.model_validate(
        {"endpoint": "http://127.0.0.1:9000", "bucket": "fleet-images", **data}
    )


def test_section_defaults_and_urls() -> None:
    section = _section(endpoint="http://127.0.0.1:9000/", access_key_id="k", secret_access_key="s")
    assert section.endpoint == "http://127.0.0.1:9000"
    assert section.resolve_secret() == "s"
    store = ObjectStore(section)
    try:
        assert store.url_of("site/r 1/x.jpg") == "http://127.0.0.1:9000/fleet-images/site/r%201/x.jpg"
    finally:
        store.close()
    public = ObjectStore(_section(public_url="https://cdn.example/images/"))
    try:
        assert public.url_of("a/b.png") == "https://cdn.example/images/a/b.png"
    finally:
        public.close()


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"bucket": "Fleet"}, "is not an S3 bucket name"),
        ({"bucket": "ab"}, "is not an S3 bucket name"),
        ({"endpoint": "ftp://x"}, "is not an http(s)://host[:port] URL"),
        ({"endpoint": "http://x/path"}, "is not an http(s)://host[:port] URL"),
        ({"prefix": "/abs"}, "no leading '/'"),
        ({"prefix": "a b"}, "a key prefix uses"),
        ({"access_key_id": "k"}, "give exactly one of"),
        ({"access_key_id": "k", "secret_access_key": "s", "secret_access_key_env": "E"}, "exactly one"),
        ({"secret_access_key": "s"}, "needs access_key_id"),
        ({"workers": 0}, "greater than or equal to 1"),
    ],
)
def test_section_refuses(data: dict[str, object], message: str) -> None:
    with pytest.raises(ValidationError, match=re.escape(message)):
        _section(**data)


def test_secret_from_file_and_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    secret = tmp_path / "secret"
    secret.write_text("from-file\n")
    assert _section(access_key_id="k", secret_access_key_file=secret).resolve_secret() == "from-file"
    monkeypatch.setenv("S3_SECRET", "from-env")
    assert _section(access_key_id="k", secret_access_key_env="S3_SECRET").resolve_secret() == "from-env"
    with pytest.raises(ObjectStoreError, match="S3_MISSING is not set"):
        _section(access_key_id="k", secret_access_key_env="S3_MISSING").resolve_secret()
    with pytest.raises(ObjectStoreError, match="cannot read"):
        _section(access_key_id="k", secret_access_key_file=tmp_path / "none").resolve_secret()
    assert _section().resolve_secret() is None
