"""The pure parts of ``fleetlink ros echo`` and ``ros pub``."""

from __future__ import annotations

import json

import pytest
import yaml

from fleetlink.cli import build_parser
from fleetlink.cli.ros_topic import known_type, parse_values, qos_option, render_message, truncated
from fleetlink.common.errors import ConfigError
from fleetlink.roswire.qos import SENSOR_DATA
from fleetlink.schemas.typestore import load_typestore


def test_long_arrays_are_cut_as_ros2_does() -> None:
    data = {"a": list(range(5)), "b": {"c": [[1, 2, 3]]}}
    assert truncated(data, 2) == {"a": [0, 1, "..."], "b": {"c": [[1, 2, "..."]]}}
    assert truncated(data, 10) == data


def test_messages_render_as_yaml_documents_or_json_lines() -> None:
    data = {"header": {"frame_id": "base"}, "data": [1, 2]}
    text = render_message(data, as_json=False)
    assert text.endswith("\n---")
    assert yaml.safe_load(text.removesuffix("---")) == data
    assert json.loads(render_message(data, as_json=True)) == data


def test_values_and_types() -> None:
    assert parse_values("{data: hi}") == {"data": "hi"}
    assert parse_values("") == {}
    with pytest.raises(ConfigError, match="not valid YAML"):
        parse_values("{data: [")
    ts = load_typestore("jazzy")
    assert known_type(ts, "std_srvs/srv/Trigger_Request") == "std_srvs/srv/Trigger_Request"
    assert known_type(ts, "std_msgs/String") == "std_msgs/msg/String"
    with pytest.raises(ConfigError, match="--msg-path"):
        known_type(ts, "my_msgs/msg/Nope")
    assert qos_option("sensor_data") == SENSOR_DATA
    assert qos_option(None) is None
    with pytest.raises(ConfigError, match="--qos"):
        qos_option("fastest")


def test_the_ros2_options_parse() -> None:
    parser = build_parser()
    args = parser.parse_args(["ros", "pub", "/chatter", "std_msgs/msg/String", "{data: hi}", "-1", "-r", "5"])
    assert (args.once, args.rate, args.values) == (True, 5.0, "{data: hi}")
    args = parser.parse_args(["ros", "echo", "/chatter", "--once", "--qos", "sensor_data", "--json"])
    assert (args.type, args.once, args.qos, args.json) == (None, True, "sensor_data", True)
