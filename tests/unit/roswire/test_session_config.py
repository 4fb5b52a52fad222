"""Session defaults mirror an rmw_zenoh node unless the user's options say otherwise (no sockets)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import zenoh

from fleetlink.common.errors import ConfigError
from fleetlink.common.zenoh_options import ZenohOptions
from fleetlink.roswire.session import ros_session_config


def get(conf: zenoh.Config, key: str) -> object:
    return json.loads(conf.get_json(key))


@pytest.mark.parametrize(
    ("options", "mode", "connect", "listen"),
    [
        (ZenohOptions(), "peer", ["tcp/127.0.0.1:7447"], ["tcp/127.0.0.1:0"]),
        (ZenohOptions(connect=("tcp/10.0.0.5:7447",)), "peer", ["tcp/10.0.0.5:7447"], ["tcp/127.0.0.1:0"]),
        (ZenohOptions(mode="client", connect=("tcp/robot:7447",)), "client", ["tcp/robot:7447"], None),
        (ZenohOptions(listen=("tcp/0.0.0.0:7448",)), "peer", ["tcp/127.0.0.1:7447"], ["tcp/0.0.0.0:7448"]),
    ],
)
def test_defaults(options: ZenohOptions, mode: str, connect: list[str], listen: list[str] | None) -> None:
    conf = ros_session_config(options)
    assert get(conf, "mode") == mode
    assert get(conf, "connect/endpoints") == connect
    if listen is not None:
        assert get(conf, "listen/endpoints") == listen
    assert get(conf, "timestamping/enabled") is True
    assert get(conf, "scouting/multicast/enabled") is False


def test_config_file_wins(tmp_path: Path) -> None:
    path = tmp_path / "z.json5"
    path.write_text('{ mode: "client", connect: { endpoints: ["tcp/1.2.3.4:7447"] } }')
    conf = ros_session_config(ZenohOptions(config_file=path))
    assert get(conf, "mode") == "client"
    assert get(conf, "connect/endpoints") == ["tcp/1.2.3.4:7447"]


def test_missing_config_file() -> None:
    with pytest.raises(ConfigError, match="not found"):
        ros_session_config(ZenohOptions(config_file=Path("/nonexistent/z.json5")))
