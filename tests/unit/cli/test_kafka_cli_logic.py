"""``fleetlink kafka``: where Kafka and the registry are, how keys and headers are shown and read."""

from __future__ import annotations

import pytest

from fleetlink.cli.kafka import headers_json, parse_headers, parse_value, places, text_or_base64
from fleetlink.common.errors import ConfigError
from fleetlink.localstack.stack import StackInfo

CCOMPAT = "http://127.0.0.1:8081/apis/ccompat/v7"
STACK = StackInfo("127.0.0.1:9092", CCOMPAT, 1, 2, 1.0, 1.0)


def test_options_beat_the_environment_which_beats_a_local_stack() -> None:
    env = {"KAFKA_BOOTSTRAP": "env:1", "SCHEMA_REGISTRY_URL": "http://env/apis/ccompat/v7"}
    assert places("opt:1", "http://opt", env, STACK) == ("opt:1", "http://opt")
    assert places(None, None, env, STACK) == ("env:1", "http://env/apis/ccompat/v7")
    assert places(None, None, {}, STACK) == ("127.0.0.1:9092", CCOMPAT)


def test_nothing_to_connect_to_is_named() -> None:
    with pytest.raises(ConfigError, match=r"give -b/--bootstrap \(or KAFKA_BOOTSTRAP\) and --registry"):
        places(None, None, {}, None)
    with pytest.raises(ConfigError, match=r"give --registry \(or SCHEMA_REGISTRY_URL\);"):
        places("k:1", None, {}, None)


def test_the_native_registry_url_is_refused_naming_the_confluent_compatible_one() -> None:
    with pytest.raises(ConfigError, match=f"--registry {CCOMPAT}$"):
        places("k:1", "http://127.0.0.1:8081/apis/registry/v3", {}, None)


def test_keys_and_headers_show_as_text_or_base64() -> None:
    assert text_or_base64(b"tb4_02") == "tb4_02"
    assert text_or_base64(b"\xff") == {"base64": "/w=="}
    assert text_or_base64(None) is None
    assert headers_json([("a", b"1"), ("b", None), ("a", b"2"), ("a", b"\xff")]) == {
        "a": ["1", "2", {"base64": "/w=="}],
        "b": None,
    }
    assert headers_json(None) == {}


def test_headers_and_values_from_the_command_line() -> None:
    assert parse_headers(["fleetlink-command-id=x=1", "empty="]) == [
        ("fleetlink-command-id", b"x=1"),
        ("empty", b""),
    ]
    with pytest.raises(ConfigError, match="expected NAME=VALUE"):
        parse_headers(["novalue"])
    assert parse_value("{a: 1, b: [x, 'y']}") == {"a": 1, "b": ["x", "y"]}
    assert parse_value('{"a": 1}') == {"a": 1}
    with pytest.raises(ConfigError, match="not valid YAML"):
        parse_value("{a: [1")
