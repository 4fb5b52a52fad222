"""Who may use the console: named users with roles (``fleetlink.console.users``), and the holder
of the admin token (the same token as the admin API), who is the bootstrap admin.

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

import base64
import hashlib
import hmac
import os
import secrets
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from pydantic import SecretStr

from fleetlink.console.errors import ConsoleConfigError
from fleetlink.console.users import Role, User, hash_password, role_at_least, verify_password

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
    """Whether ``given`` (surrounding blanks removed) is the token, compared in constant time."""
    return hmac.compare_digest(given.strip().encode(), token.get_secret_value().encode())


def bearer(header: str | None) -> str | None:
    """The token of an ``Authorization: Bearer <token>`` header (``None`` for other schemes)."""
    if header is None:
        return None
    scheme, _, given = header.strip().partition(" ")
    return given.strip() if scheme.lower() == "bearer" else None


@dataclass(frozen=True, slots=True)
class Access:
    """What :func:`check` decided: whether the request may read, and whether a session cookie proved it."""

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


# -- named users and roles (fleetlink.console.users) ------------------------------------------

TOKEN_USER = "token"  # noqa: S105 - a user name, not a secret
"""Who the holder of the admin token is in the audit records: the bootstrap admin."""


@dataclass(frozen=True, slots=True)
class Identity:
    """Who a request is: the user, their role and whether a session cookie proved it."""

    user: str
    role: Role
    by_cookie: bool = False

    def may(self, needed: Role) -> bool:
        """Whether this identity's role is ``needed`` or above."""
        return role_at_least(self.role, needed)


OPEN = Identity(user="anonymous", role="admin")
"""Without a token and without users the console is open (loopback only: docs/security.md)."""


def basic(header: str | None) -> tuple[str, str] | None:
    """The user and password of an ``Authorization: Basic`` header."""
    if header is None:
        return None
    scheme, _, given = header.strip().partition(" ")
    if scheme.lower() != "basic":
        return None
    try:
        user, sep, password = base64.b64decode(given.strip(), validate=True).decode("utf-8").partition(":")
    except (ValueError, UnicodeDecodeError):
        return None
    return (user, password) if sep else None


class Authenticator:
    """Who a request is: the admin token's holder (role ``admin``), a named user of the users
    file with their role, or nobody. Sessions: the token's keep the cookie of ``cookie_value``
    (keyed by the token); a user's is ``u~<name>~<expires>~<mac>``, the MAC keyed by a secret of
    this process over the name, the expiry and the user's fingerprint (a new password or role
    ends the user's sessions; so does restarting the console)."""

    def __init__(
        self,
        token: SecretStr | None,
        users: Mapping[str, User] | None = None,
        *,
        ttl_s: float = SESSION_TTL_S,
        secret: bytes | None = None,
    ) -> None:
        self.token = token
        self.users = dict(users or {})
        self.ttl_s = ttl_s
        self._secret = secret if secret is not None else secrets.token_bytes(32)

    @property
    def open(self) -> bool:
        """Whether anyone may use the console: no token and no users configured."""
        return self.token is None and not self.users

    def identify(
        self, *, authorization: str | None, cookie: str | None, now: float
    ) -> tuple[Identity | None, bool]:
        """(who, whether a credential was tried in a header: the caller counts wrong ones)."""
        if self.open:
            return OPEN, False
        given = bearer(authorization)
        if given is not None:
            ok = self.token is not None and token_matches(self.token, given)
            return (Identity(TOKEN_USER, "admin") if ok else None), True
        pair = basic(authorization)
        if pair is not None:
            return self.sign_in(pair[0], pair[1]), True
        if cookie:
            return self._session(cookie, now), False
        return None, False

    def sign_in(self, name: str, secret: str) -> Identity | None:
        """The sign-in form: a user's name and password, or no name and the admin token."""
        name = name.strip()
        if not name:
            if self.token is not None and token_matches(self.token, secret):
                return Identity(TOKEN_USER, "admin")
            return None
        user = self.users.get(name)
        if user is None:
            verify_password(_DUMMY_HASH, secret)  # the same time for a name that does not exist
            return None
        return Identity(user.name, user.role) if verify_password(user.password_hash, secret) else None

    def cookie(self, identity: Identity, *, now: float) -> str:
        """A session cookie for ``identity`` that expires ``ttl_s`` after ``now``: :func:`cookie_value`'s
        for the token's holder, ``u~<name>~<expires>~<mac>`` for a named user."""
        if identity.user == TOKEN_USER and self.token is not None:
            return cookie_value(self.token, now=now, ttl_s=self.ttl_s)
        user = self.users[identity.user]
        expires = int(now + self.ttl_s)
        return f"u~{user.name}~{expires}~{self._user_mac(user, expires)}"

    def _user_mac(self, user: User, expires: int) -> str:
        text = f"{user.name}\0{expires}\0{user.fingerprint}".encode()
        return hmac.new(self._secret, _CONTEXT + text, hashlib.sha256).hexdigest()

    def _session(self, cookie: str, now: float) -> Identity | None:
        if cookie.startswith("u~"):
            parts = cookie.split("~")
            if len(parts) != 4 or not parts[2].isdigit() or len(parts[2]) > 12:
                return None
            user = self.users.get(parts[1])
            expires = int(parts[2])
            if user is None or now >= expires:
                return None
            if not hmac.compare_digest(parts[3].encode(), self._user_mac(user, expires).encode()):
                return None
            return Identity(user.name, user.role, by_cookie=True)
        if self.token is not None and session_valid(self.token, cookie, now=now):
            return Identity(TOKEN_USER, "admin", by_cookie=True)
        return None


_DUMMY_HASH = hash_password("not a password", salt=b"fleetlink-dummy-salt")
