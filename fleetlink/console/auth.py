"""Who may use the console: the holder of the admin token (the same token as the admin API).

A browser signs in once with a form; the console then sets an ``HttpOnly``, ``SameSite=Strict``
cookie holding the session's expiry time and a keyed hash of it under the token (never the
token itself), which it checks on every request, constant-time: a session ends after
``session_ttl`` (8 h by default), and changing the token ends every session. Scripts may send
``Authorization: Bearer <token>`` instead. After a few wrong tokens (form or header) a client
is locked out for a while (``fleetlink.common.login_limiter``). A change
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
SESSION_TTL_S = 8 * 3600.0
_CONTEXT = b"fleetlink console session v2\x00"


def _session_mac(token: SecretStr, expires: int) -> str:
    return hmac.new(
        token.get_secret_value().encode(), _CONTEXT + str(expires).encode(), hashlib.sha256
    ).hexdigest()


def cookie_value(token: SecretStr, *, now: float, ttl_s: float = SESSION_TTL_S) -> str:
    """A session cookie valid until ``now + ttl_s``: ``<expires>.<HMAC-SHA256 keyed by the token>``."""
    expires = int(now + ttl_s)
    return f"{expires}.{_session_mac(token, expires)}"


def session_valid(token: SecretStr, cookie: str, *, now: float) -> bool:
    """Does ``cookie`` prove the token, and has its session not expired?"""
    expires_text, _, mac = cookie.partition(".")
    if not expires_text.isdigit() or len(expires_text) > 12:
        return False
    expires = int(expires_text)
    return now < expires and hmac.compare_digest(mac.encode(), _session_mac(token, expires).encode())


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


def check(token: SecretStr | None, *, authorization: str | None, cookie: str | None, now: float) -> Access:
    """May this request read the console? (``by_cookie``: proven by an unexpired session cookie.)"""
    if token is None:
        return Access(allowed=True)
    given = bearer(authorization)
    if given is not None and token_matches(token, given):
        return Access(allowed=True)
    if cookie is not None and session_valid(token, cookie, now=now):
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
