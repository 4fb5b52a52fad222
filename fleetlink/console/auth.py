"""Who may use the console: the holder of the admin token (the same token as the admin API).

A browser signs in once with a form; the console then sets an ``HttpOnly``, ``SameSite=Strict``
cookie holding a keyed hash of the token (never the token itself), which it checks on every
request, constant-time. Scripts may send ``Authorization: Bearer <token>`` instead. A change
made with the cookie must also carry the ``X-Fleetlink-Console`` header, which a page of another
site cannot add without the console's consent (CORS), so a cross-site form cannot change
mappings. Without a token configured the console is open, like the admin API (keep it on
loopback then).
"""

from __future__ import annotations

import hashlib
import hmac
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from pydantic import SecretStr

from fleetlink.console.errors import ConsoleConfigError

COOKIE = "fleetlink_console"
CHANGE_HEADER = "x-fleetlink-console"
_CONTEXT = b"fleetlink console session v1"


def cookie_value(token: SecretStr) -> str:
    """The cookie that proves the token: HMAC-SHA256 of a fixed text keyed by the token."""
    return hmac.new(token.get_secret_value().encode(), _CONTEXT, hashlib.sha256).hexdigest()


def token_matches(token: SecretStr, given: str) -> bool:
    return hmac.compare_digest(given.strip().encode(), token.get_secret_value().encode())


def bearer(header: str | None) -> str | None:
    """The token of an ``Authorization: Bearer <token>`` header (``None`` for other schemes)."""
    if header is None:
        return None
    scheme, _, given = header.strip().partition(" ")
    return given.strip() if scheme.lower() == "bearer" else None


@dataclass(frozen=True, slots=True)
class Access:
    allowed: bool
    by_cookie: bool = False


def check(token: SecretStr | None, *, authorization: str | None, cookie: str | None) -> Access:
    """May this request read the console? (``by_cookie``: proven by the session cookie.)"""
    if token is None:
        return Access(allowed=True)
    given = bearer(authorization)
    if given is not None and token_matches(token, given):
        return Access(allowed=True)
    if cookie is not None and hmac.compare_digest(cookie.encode(), cookie_value(token).encode()):
        return Access(allowed=True, by_cookie=True)
    return Access(allowed=False)


def may_change(token: SecretStr | None, access: Access, headers: Mapping[str, str]) -> bool:
    """May this request change something? Cookie sessions must send the console's header."""
    if not access.allowed:
        return False
    return token is None or not access.by_cookie or headers.get(CHANGE_HEADER) == "1"


def load_console_token(
    env_name: str | None, file: Path | None, env: Mapping[str, str] | None = None
) -> SecretStr | None:
    """The token from ``file`` (wins) or the environment variable ``env_name``; ``None`` when
    neither is set. An unreadable or empty file is an error."""
    env = os.environ if env is None else env
    if file is not None:
        try:
            text = file.read_text(encoding="utf-8").strip()
        except OSError as exc:
            raise ConsoleConfigError(f"{file}: cannot read the console token file: {exc.strerror}") from None
        if not text:
            raise ConsoleConfigError(f"{file}: the console token file is empty")
        return SecretStr(text)
    value = env.get(env_name, "").strip() if env_name else ""
    return SecretStr(value) if value else None
