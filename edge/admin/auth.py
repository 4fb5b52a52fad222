"""The admin token: where it comes from and how a request proves it knows it.

The token comes from the environment (``FLEETLINK_ADMIN_TOKEN``) or a file
(``FLEETLINK_ADMIN_TOKEN_FILE``, or a path given by the caller; surrounding whitespace is
ignored). With a token configured, every admin request must carry ``Authorization: Bearer
<token>`` (over Zenoh: the same text as the query's attachment). The token is held as a
``SecretStr`` and never logged; comparison is constant-time.
"""

from __future__ import annotations

import hmac
import os
from collections.abc import Mapping
from pathlib import Path

from pydantic import SecretStr

from fleetlink.edge.admin.errors import TokenError

ENV_TOKEN = "FLEETLINK_ADMIN_TOKEN"  # noqa: S105 - the variable's name, not a secret
ENV_TOKEN_FILE = "FLEETLINK_ADMIN_TOKEN_FILE"  # noqa: S105 - a variable name


def load_token(env: Mapping[str, str] | None = None, file: Path | None = None) -> SecretStr | None:
    """The configured token, or ``None`` (no token: the API is open; keep it on loopback).
    ``file`` wins over the environment; an unreadable or empty file is an error."""
    env = os.environ if env is None else env
    path = file or (Path(env[ENV_TOKEN_FILE]) if env.get(ENV_TOKEN_FILE) else None)
    if path is not None:
        try:
            text = path.read_text(encoding="utf-8").strip()
        except OSError as exc:
            raise TokenError(f"{path}: cannot read the admin token file: {exc.strerror}") from None
        if not text:
            raise TokenError(f"{path}: the admin token file is empty")
        return SecretStr(text)
    value = env.get(ENV_TOKEN, "").strip()
    return SecretStr(value) if value else None


def authorized(token: SecretStr | None, header: str | bytes | None) -> bool:
    """Does ``header`` (``Bearer <token>``) prove the token? Always true without a token."""
    if token is None:
        return True
    if header is None:
        return False
    text = header.decode("utf-8", "replace") if isinstance(header, bytes) else header
    scheme, _, given = text.strip().partition(" ")
    if scheme.lower() != "bearer":
        return False
    return hmac.compare_digest(given.strip().encode(), token.get_secret_value().encode())
