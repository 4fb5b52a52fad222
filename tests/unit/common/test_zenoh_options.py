"""Zenoh's usual options: file first, explicit options on top; errors name the option."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from fleetlink.common.errors import ConfigError
from fleetlink.common.zenoh_options import ZenohOptions, ZenohSection, add_zenoh_arguments, options_from_args


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_zenoh_arguments(parser)
    return parser.parse_args(argv)


def test_flags_become_config_values() -> None:
    args = _parse(
        [
            "-m",
            "client",
            "-e",
            "tcp/127.0.0.1:7447",
            "-e",
            "tcp/127.0.0.1:7448",
            "--cfg",
            "timestamping/enabled:true",
            "--domain-id",
            "3",
        ]
    )
    conf = options_from_args(args).to_config()
    assert json.loads(conf.get_json("mode")) == "client"
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7447", "tcp/127.0.0.1:7448"]
    assert json.loads(conf.get_json("timestamping/enabled")) is True
    assert args.domain_id == 3


def test_file_then_flags(tmp_path: Path) -> None:
    path = tmp_path / "z.json5"
    path.write_text('{ mode: "peer", connect: { endpoints: ["tcp/127.0.0.1:1"] } }')
    conf = ZenohOptions(config_file=path, connect=("tcp/127.0.0.1:2",)).to_config()
    assert json.loads(conf.get_json("mode")) == "peer"
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/127.0.0.1:2"]


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (ZenohOptions(config_file=Path("/nonexistent/z.json5")), "zenoh config file not found"),
        (ZenohOptions(overrides=(("mode", '"sideways"'),)), "zenoh option mode="),
    ],
)
def test_bad_options_are_named(options: ZenohOptions, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        options.to_config()


def test_bad_cfg_flag() -> None:
    with pytest.raises(ConfigError, match="expected KEY:JSON5_VALUE"):
        options_from_args(_parse(["--cfg", "nocolon"]))


def test_domain_id_from_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "7")
    assert _parse([]).domain_id == 7


def test_section_merges_with_command_line() -> None:
    section = ZenohSection(mode="router", listen=["tcp/0.0.0.0:7447"], connect=["tcp/cloud:7447"])
    merged = section.merged_with(ZenohOptions(connect=("tcp/other:7447",)))
    assert merged.mode == "router"
    assert merged.listen == ("tcp/0.0.0.0:7447",)
    assert merged.connect == ("tcp/other:7447",)
