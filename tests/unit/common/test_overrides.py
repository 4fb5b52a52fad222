"""``--set KEY=VALUE`` and ``$FLEETLINK_SET``: parsed, applied in order, errors by YAML path."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import BaseModel, ConfigDict

from fleetlink.common.configfile import load_config
from fleetlink.common.errors import ConfigError
from fleetlink.common.overrides import apply_overrides, collect_overrides, overrides_from_env, parse_override
from fleetlink.common.yaml_paths import format_path, parse_path


@pytest.mark.parametrize(
    ("text", "parts"),
    [
        ("spool.dir", ("spool", "dir")),
        ("robot_types.tb4.mappings[0].to", ("robot_types", "tb4", "mappings", 0, "to")),
        ('kafka.producer_overrides."batch.size"', ("kafka", "producer_overrides", "batch.size")),
        ("a[1][2]", ("a", 1, 2)),
    ],
)
def test_paths_parse(text: str, parts: tuple[str | int, ...]) -> None:
    assert parse_path(text) == parts


@pytest.mark.parametrize("text", ["", "a..b", "a.", "a[x]", "a b", ".a"])
def test_bad_paths_are_refused(text: str) -> None:
    with pytest.raises(ValueError, match=r"YAML path|unexpected"):
        parse_path(text)


def test_format_is_the_inverse_for_plain_keys() -> None:
    assert format_path(parse_path("mappings[0].to")) == "mappings[0].to"


@pytest.mark.parametrize(
    ("text", "value"),
    [
        ("zenoh.connect=[tcp/10.0.0.5:7447]", ["tcp/10.0.0.5:7447"]),
        ("ros.domain_id=7", 7),
        ("admin.listen=0.0.0.0:8480", "0.0.0.0:8480"),
        ("site=", ""),
        ("note=a=b", "a=b"),
    ],
)
def test_values_are_yaml(text: str, value: object) -> None:
    assert parse_override(text).value == value


@pytest.mark.parametrize("text", ["novalue", "=x", "a=[unclosed"])
def test_bad_overrides_name_themselves(text: str) -> None:
    with pytest.raises(ConfigError, match=r"--set"):
        parse_override(text)


def test_apply_creates_what_is_missing_and_leaves_the_input_alone() -> None:
    data = {"spool": {"dir": "/a"}, "mappings": [{"name": "x"}]}
    out = apply_overrides(
        data,
        [
            parse_override("spool.dir=/b"),
            parse_override("admin.listen=127.0.0.1:1"),
            parse_override("mappings[0].to=t"),
            parse_override("mappings[1].name=y"),
        ],
    )
    assert out == {
        "spool": {"dir": "/b"},
        "mappings": [{"name": "x", "to": "t"}, {"name": "y"}],
        "admin": {"listen": "127.0.0.1:1"},
    }
    assert data == {"spool": {"dir": "/a"}, "mappings": [{"name": "x"}]}


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("mappings[5].to=t", r"mappings has 1 item\(s\): \[5\] is past the next one"),
        ("spool[0]=x", "spool is not a list"),
        ("spool.dir.deeper=x", "spool.dir is not a mapping"),
    ],
)
def test_apply_errors_say_where(text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        apply_overrides({"spool": {"dir": "/a"}, "mappings": [{}]}, [parse_override(text)])


def test_env_holds_one_per_line_and_set_options_come_last() -> None:
    env = {"FLEETLINK_SET": "# comment\nsite=a\n\n  spool.dir=/x  \n"}
    assert [o.text for o in overrides_from_env(env)] == ["site=a", "spool.dir=/x"]
    overrides = collect_overrides(env, ["site=b"])
    assert [o.source for o in overrides] == ["$FLEETLINK_SET", "$FLEETLINK_SET", "--set"]
    assert apply_overrides({}, overrides)["site"] == "b"


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")
    port: int
    name: str = "x"


def test_errors_in_set_values_say_where_they_came_from(tmp_path: Path) -> None:
    path = tmp_path / "c.yaml"
    path.write_text("port: 1\nname: a\n")
    assert load_config(_Model, path, [parse_override("port=2")]).port == 2
    with pytest.raises(ConfigError) as info:
        load_config(_Model, path, [parse_override("port=many")])
    assert "port (set by --set): Input should be a valid integer" in str(info.value)
    with pytest.raises(ConfigError, match=r"nmae \(set by --set\): unknown key"):
        load_config(_Model, path, [parse_override("nmae=b")])
