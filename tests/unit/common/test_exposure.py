"""Admin surfaces beyond loopback need a token: a start-up error naming the config key."""

from __future__ import annotations

import logging

import pytest

from fleetlink.common.errors import ConfigError
from fleetlink.common.exposure import check_exposure, is_loopback

log = logging.getLogger("test")


@pytest.mark.parametrize(
    ("host", "loopback"),
    [
        ("127.0.0.1", True),
        ("127.1.2.3", True),
        ("::1", True),
        ("[::1]", True),
        ("localhost", True),
        ("0.0.0.0", False),
        ("::", False),
        ("10.0.0.5", False),
        ("admin.example.com", False),
        ("", False),
    ],
)
def test_is_loopback(host: str, loopback: bool) -> None:
    assert is_loopback(host) is loopback


def check(listen: str, has_token: bool) -> None:
    check_exposure(
        listen,
        has_token=has_token,
        key="admin.listen",
        what="the admin API",
        credentials_from="FLEETLINK_ADMIN_TOKEN",
        log=log,
    )


def test_beyond_loopback_without_a_token_is_refused(caplog: pytest.LogCaptureFixture) -> None:
    with pytest.raises(ConfigError, match=r"admin\.listen: the admin API would listen on 0\.0\.0\.0:8480"):
        check("0.0.0.0:8480", has_token=False)
    check("0.0.0.0:8480", has_token=True)
    with caplog.at_level(logging.WARNING):
        check("127.0.0.1:8480", has_token=False)
    assert "has no access token" in caplog.text
