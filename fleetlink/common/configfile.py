"""Load one YAML file into one typed config model, with errors that name the YAML path.

Every fleetlink process has one config model, and every model of every section derives from
``Section``: unknown keys are refused, durations are text (``fleetlink.common.durations``) and
names have one type each (``fleetlink.common.names``). ``load_config`` reads the file,
validates it and, on failure, raises a ``ConfigError`` listing every problem as
``path.to[0].field (line N): message``. No socket is opened.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

from fleetlink.common.errors import ConfigError

ModelT = TypeVar("ModelT", bound=BaseModel)


class Section(BaseModel):
    """The base of every config model and section: a key it does not declare is an error (a
    misspelt key would otherwise leave its default in force without a word). A subclass's own
    ``model_config`` adds to this one."""

    model_config = ConfigDict(extra="forbid")


PathPart = str | int


def format_path(parts: Sequence[PathPart]) -> str:
    """``("mappings", 0, "to")`` -> ``mappings[0].to``."""
    text = ""
    for part in parts:
        if isinstance(part, int):
            text += f"[{part}]"
        else:
            text += f".{part}" if text else str(part)
    return text or "<root>"


def _line_index(node: yaml.Node, prefix: tuple[PathPart, ...], out: dict[tuple[PathPart, ...], int]) -> None:
    out.setdefault(prefix, node.start_mark.line + 1)
    if isinstance(node, yaml.MappingNode):
        for key_node, value_node in node.value:
            key = key_node.value
            out[(*prefix, key)] = key_node.start_mark.line + 1
            _line_index(value_node, (*prefix, key), out)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            _line_index(item, (*prefix, i), out)


def _nearest_line(lines: Mapping[tuple[PathPart, ...], int], loc: tuple[PathPart, ...]) -> int | None:
    for end in range(len(loc), 0, -1):
        line = lines.get(loc[:end])
        if line is not None:
            return line
    return None


def validation_messages(
    exc: ValidationError, lines: Mapping[tuple[PathPart, ...], int] | None = None
) -> list[str]:
    """One line per error: YAML path, line number when known, and pydantic's message."""
    messages = []
    for err in exc.errors(include_url=False):
        loc = tuple(p for p in err["loc"] if isinstance(p, str | int))
        # pydantic puts the tag of a discriminated union / function validator in loc; drop non-keys
        line = _nearest_line(lines or {}, loc)
        where = format_path(loc) + (f" (line {line})" if line else "")
        msg = err["msg"]
        if err["type"] == "extra_forbidden":
            msg = "unknown key (not allowed here; check the spelling)"
        messages.append(f"{where}: {msg}")
    return messages


def read_yaml(path: Path) -> tuple[Any, dict[tuple[PathPart, ...], int]]:
    """Parse a YAML file; returns the data and a map from YAML path to line number."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{path}: config file not found") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config file: {exc.strerror}") from None
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from None
    lines: dict[tuple[PathPart, ...], int] = {}
    if node is not None:
        _line_index(node, (), lines)
    return data, lines


def validate_data(
    model: type[ModelT], data: Any, *, source: str, lines: Mapping[tuple[PathPart, ...], int] | None = None
) -> ModelT:
    if data is None:
        data = {}
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        problems = validation_messages(exc, lines)
        listing = "\n  ".join(problems)
        raise ConfigError(f"{source}: {len(problems)} problem(s) in the config:\n  {listing}") from None


def load_config(model: type[ModelT], path: Path) -> ModelT:
    """Read and validate ``path`` as ``model``; raises ``ConfigError`` naming each bad YAML path."""
    data, lines = read_yaml(path)
    return validate_data(model, data, source=str(path), lines=lines)
