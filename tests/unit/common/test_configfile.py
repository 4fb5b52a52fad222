"""Config files: every problem is reported with its YAML path and line."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import pytest
from pydantic import BaseModel, ConfigDict, Field

from fleetlink.common.configfile import format_path, load_config
from fleetlink.common.errors import ConfigError


class Mapping(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str
    throttle_hz: float = Field(default=0, ge=0)


class Producer(BaseModel):
    model_config = ConfigDict(extra="forbid")
    acks: Literal["all"] = "all"


class Config(BaseModel):
    model_config = ConfigDict(extra="forbid")
    site: str
    mappings: list[Mapping] = []
    producer: Producer = Producer()


@pytest.mark.parametrize(
    ("parts", "text"),
    [((), "<root>"), (("site",), "site"), (("mappings", 0, "name"), "mappings[0].name"), ((3,), "[3]")],
)
def test_format_path(parts: tuple[str | int, ...], text: str) -> None:
    assert format_path(parts) == text


@pytest.mark.parametrize(
    ("yaml_text", "expected"),
    [
        ("site: a\nmappings:\n  - name: ir\n    throttle_hz: fast\n", "mappings[0].throttle_hz (line 4)"),
        ("site: a\nmapings: []\n", "mapings (line 2): unknown key"),
        ("mappings: []\n", "site: Field required"),
        ("site: a\nproducer:\n  acks: 1\n", "producer.acks (line 3)"),
        ("site: a\nmappings:\n  - {name: ir}\n  - {name: odom, extra: 1}\n", "mappings[1].extra (line 4)"),
    ],
)
def test_errors_name_the_yaml_path(tmp_path: Path, yaml_text: str, expected: str) -> None:
    path = tmp_path / "c.yaml"
    path.write_text(yaml_text)
    with pytest.raises(ConfigError) as err:
        load_config(Config, path)
    assert expected in str(err.value)
    assert str(path) in str(err.value)


def test_missing_file_and_bad_yaml(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="config file not found"):
        load_config(Config, tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("site: [unclosed\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(Config, bad)


def test_valid_config_loads(tmp_path: Path) -> None:
    path = tmp_path / "ok.yaml"
    path.write_text("site: warehouse-a\nmappings:\n  - name: ir\n    throttle_hz: 10\n")
    config = load_config(Config, path)
    assert config.site == "warehouse-a"
    assert config.mappings[0].throttle_hz == 10
