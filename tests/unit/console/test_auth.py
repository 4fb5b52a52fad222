"""fleetlink.console.auth: the token, the session cookie, the change header."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import SecretStr

from fleetlink.console.auth import (
    SESSION_TTL_S,
    Access,
    bearer,
    check,
    cookie_value,
    load_console_token,
    may_change,
    session_valid,
)
from fleetlink.console.errors import ConsoleConfigError

TOKEN = SecretStr("s3cret-token")
NOW = 1_000_000.0
COOKIE = cookie_value(TOKEN, now=NOW)


def test_the_cookie_proves_the_token_without_holding_it() -> None:
    assert TOKEN.get_secret_value() not in COOKIE
    expires, _, mac = COOKIE.partition(".")
    assert (int(expires), len(mac)) == (NOW + SESSION_TTL_S, 64)
    assert cookie_value(SecretStr("s3cret-token"), now=NOW) == COOKIE
    assert cookie_value(SecretStr("other"), now=NOW) != COOKIE


def test_a_session_cookie_expires_and_its_time_cannot_be_moved() -> None:
    assert session_valid(TOKEN, COOKIE, now=NOW + SESSION_TTL_S - 1)
    assert not session_valid(TOKEN, COOKIE, now=NOW + SESSION_TTL_S)
    expires, _, mac = COOKIE.partition(".")
    assert not session_valid(TOKEN, f"{int(expires) + 3600}.{mac}", now=NOW)
    for junk in ("", ".", "x.y", "-1.abc", "9" * 20 + ".abc"):
        assert not session_valid(TOKEN, junk, now=NOW)


@pytest.mark.parametrize(
    ("header", "expected"),
    [
        (None, None),
        ("Bearer abc", "abc"),
        ("bearer  abc ", "abc"),
        ("Basic abc", None),
        ("Bearer", ""),
        ("", None),
    ],
)
def test_bearer(header: str | None, expected: str | None) -> None:
    assert bearer(header) == expected


@pytest.mark.parametrize(
    ("token", "authorization", "cookie", "expected"),
    [
        (None, None, None, Access(allowed=True)),
        (TOKEN, None, None, Access(allowed=False)),
        (TOKEN, "Bearer s3cret-token", None, Access(allowed=True)),
        (TOKEN, "Bearer wrong", None, Access(allowed=False)),
        (TOKEN, "Basic s3cret-token", None, Access(allowed=False)),
        (TOKEN, "s3cret-token", None, Access(allowed=False)),
        (TOKEN, None, COOKIE, Access(allowed=True, by_cookie=True)),
        (TOKEN, None, "s3cret-token", Access(allowed=False)),  # the token itself is not a cookie
        (TOKEN, None, COOKIE[:-1] + "0", Access(allowed=False)),
        (TOKEN, "Bearer wrong", COOKIE, Access(allowed=True, by_cookie=True)),
    ],
)
def test_check(
    token: SecretStr | None, authorization: str | None, cookie: str | None, expected: Access
) -> None:
    assert check(token, authorization=authorization, cookie=cookie, now=NOW) == expected


@pytest.mark.parametrize(
    ("token", "access", "headers", "expected"),
    [
        (TOKEN, Access(allowed=False), {"x-fleetlink-console": "1"}, False),
        (TOKEN, Access(allowed=True), {}, True),  # a bearer token: a script, not a page
        (TOKEN, Access(allowed=True, by_cookie=True), {}, False),  # a cross-site form would look like this
        (TOKEN, Access(allowed=True, by_cookie=True), {"x-fleetlink-console": "1"}, True),
        (TOKEN, Access(allowed=True, by_cookie=True), {"x-fleetlink-console": "yes"}, False),
        (None, Access(allowed=True), {}, True),
    ],
)
def test_may_change(token: SecretStr | None, access: Access, headers: dict[str, str], expected: bool) -> None:
    assert may_change(token, access, headers) is expected


def test_load_console_token(tmp_path: Path) -> None:
    env = {"TOK": "  from-env \n", "EMPTY": " "}
    assert load_console_token("TOK", None, env) == SecretStr("from-env")
    assert load_console_token("EMPTY", None, env) is None
    assert load_console_token("MISSING", None, env) is None
    assert load_console_token(None, None, env) is None
    file = tmp_path / "token"
    file.write_text("from-file\n")
    assert load_console_token("TOK", file, env) == SecretStr("from-file")
    file.write_text("\n")
    with pytest.raises(ConsoleConfigError, match="is empty"):
        load_console_token("TOK", file, env)
    with pytest.raises(ConsoleConfigError, match="cannot read the console token file"):
        load_console_token("TOK", tmp_path / "absent", env)
