"""The fleet console is closed by default: beyond loopback without a token or users, the uplink
does not start, and the error names ``console.listen`` (the edge's admin API: row 36)."""

from __future__ import annotations

from pathlib import Path

import pytest

from fleetlink.common.errors import ConfigError
from fleetlink.console.uplink import console_extensions
from fleetlink.console.users import hash_password
from fleetlink.uplink.config import UplinkConfig

pytestmark = pytest.mark.unit


def config(**console: object) -> UplinkConfig:
    return UplinkConfig.model_validate(
        {
            "kafka": {"bootstrap_servers": "127.0.0.1:9092"},
            "registry": {"url": "http://127.0.0.1:8081"},
            "console": {"token_env": "FLEETLINK_TEST_NO_SUCH_TOKEN", **console},
        }
    )


def test_beyond_loopback_without_credentials_the_uplink_does_not_start(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv("FLEETLINK_TEST_NO_SUCH_TOKEN", raising=False)
    with pytest.raises(
        ConfigError, match=r"console\.listen: the fleet console would listen on 0\.0\.0\.0:8490"
    ):
        console_extensions(config(listen="0.0.0.0:8490"))
    assert len(console_extensions(config(listen="127.0.0.1:8490"))) == 1  # loopback: a warning only


def test_a_token_or_named_users_open_it_beyond_loopback(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("FLEETLINK_TEST_NO_SUCH_TOKEN", "a-long-enough-test-token")
    assert len(console_extensions(config(listen="0.0.0.0:8490"))) == 1
    monkeypatch.delenv("FLEETLINK_TEST_NO_SUCH_TOKEN")
    users = tmp_path / "users.yaml"
    users.write_text(
        f"users:\n  - {{name: lin, role: admin, password_hash: '{hash_password('admin-pass-1')}'}}\n"
    )
    assert len(console_extensions(config(listen="0.0.0.0:8490", users_file=str(users)))) == 1
