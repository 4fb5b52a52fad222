"""The ``objects:`` section: an S3-compatible object store for claim-checked payloads."""

from __future__ import annotations

import os
import re
from pathlib import Path

from pydantic import (
    ByteSize,
    Field,
    SecretStr,
    SerializationInfo,
    field_serializer,
    field_validator,
    model_validator,
)

from fleetlink.common.configfile import Section
from fleetlink.common.durations import Seconds
from fleetlink.common.objects.errors import ObjectStoreError

_BUCKET = re.compile(r"^[a-z0-9][a-z0-9.-]{1,61}[a-z0-9]$")
_PREFIX = re.compile(r"^[A-Za-z0-9._/-]*$")
_ENDPOINT = re.compile(r"^https?://[^/?#\s]+$")


class ObjectStoreSection(Section):
    """Where claim-checked payloads go (S3 API, path-style requests, Signature Version 4)."""

    endpoint: str = Field(
        examples=["https://s3.eu-central-1.amazonaws.com", "http://127.0.0.1:9000"],
        description="base URL of the S3 API (scheme, host and port; no path)",
    )
    bucket: str = Field(examples=["fleet-images"], description="the bucket objects are put in")
    region: str = Field(default="us-east-1", min_length=1, description="the region requests are signed for")
    access_key_id: str | None = Field(
        default=None, description="the access key; without it requests go unsigned (a store open to all)"
    )
    secret_access_key: SecretStr | None = Field(default=None, description="the secret key, inline")
    secret_access_key_file: Path | None = Field(default=None, description="a file holding the secret key")
    secret_access_key_env: str | None = Field(
        default=None, description="an environment variable holding the secret key"
    )
    prefix: str = Field(
        default="",
        description="object keys start with this (letters, digits, '._/-'), e.g. 'fleet/'; then "
        "<site>/<robot>/<mapping>/<stamp>-<sha256>.<ext>",
    )
    public_url: str | None = Field(
        default=None,
        description="base URL written into records instead of <endpoint>/<bucket> (a CDN, a proxy)",
    )
    create_bucket: bool = Field(
        default=False, description="create the bucket at start-up when it does not exist (test beds)"
    )
    request_timeout: Seconds = Field(default=10.0, gt=0, le=600, description="one request, at most")
    workers: int = Field(default=4, ge=1, le=64, description="uploads at once (the edge)")
    max_pending_bytes: ByteSize = Field(
        default=ByteSize(256 << 20),
        description="payloads waiting for upload, at most (the edge): beyond it a record is "
        "dead-lettered at once instead of waiting",
    )
    retry_backoff_max: Seconds = Field(
        default=30.0, gt=0, le=3600, description="longest pause between two attempts of a failed upload"
    )

    @field_serializer("secret_access_key", when_used="json")
    def _dump_secret(self, value: SecretStr | None, info: SerializationInfo) -> str | None:
        """``**********``, except in a dump that is to validate again (the edge's admin overlay
        dumps the file's config with ``{"reveal_secrets": True}``)."""
        if value is None:
            return None
        context = info.context
        if isinstance(context, dict) and context.get("reveal_secrets"):
            return value.get_secret_value()
        return str(value)

    @field_validator("endpoint")
    @classmethod
    def _endpoint(cls, value: str) -> str:
        value = value.rstrip("/")
        if not _ENDPOINT.match(value):
            raise ValueError(f"{value!r} is not an http(s)://host[:port] URL (no path)")
        return value

    @field_validator("public_url")
    @classmethod
    def _public_url(cls, value: str | None) -> str | None:
        if value is None:
            return None
        if not value.startswith(("http://", "https://")) or any(c.isspace() for c in value):
            raise ValueError(f"{value!r} is not an http(s):// URL")
        return value.rstrip("/")

    @field_validator("bucket")
    @classmethod
    def _bucket(cls, value: str) -> str:
        if not _BUCKET.match(value) or ".." in value:
            raise ValueError(
                f"{value!r} is not an S3 bucket name (3-63 lowercase letters, digits, '.' and '-', "
                "starting and ending with a letter or digit)"
            )
        return value

    @field_validator("prefix")
    @classmethod
    def _prefix(cls, value: str) -> str:
        if not _PREFIX.match(value) or value.startswith("/") or "//" in value:
            raise ValueError(f"{value!r}: a key prefix uses letters, digits and '._/-', and no leading '/'")
        return value

    @model_validator(mode="after")
    def _secret(self) -> ObjectStoreSection:
        given = [
            x
            for x in (self.secret_access_key, self.secret_access_key_file, self.secret_access_key_env)
            if x is not None
        ]
        if self.access_key_id is None and given:
            raise ValueError("a secret key needs access_key_id")
        if self.access_key_id is not None and len(given) != 1:
            raise ValueError(
                "with access_key_id give exactly one of secret_access_key, secret_access_key_file, "
                "secret_access_key_env"
            )
        return self

    def resolve_secret(self) -> str | None:
        """The secret key (read from its file or variable now), or None for unsigned requests."""
        if self.access_key_id is None:
            return None
        if self.secret_access_key is not None:
            return self.secret_access_key.get_secret_value()
        if self.secret_access_key_file is not None:
            try:
                return self.secret_access_key_file.read_text(encoding="utf-8").strip()
            except OSError as exc:
                raise ObjectStoreError(
                    f"objects.secret_access_key_file: cannot read {self.secret_access_key_file}: "
                    f"{exc.strerror or exc}",
                    retriable=False,
                ) from None
        name = self.secret_access_key_env or ""
        value = os.environ.get(name)
        if value is None:
            raise ObjectStoreError(
                f"objects.secret_access_key_env: environment variable {name} is not set", retriable=False
            )
        return value
