"""Load one YAML file into one typed config model, with errors that name the YAML path.

Every fleetlink process has one config model, and every model of every section derives from
``Section``: unknown keys are refused, durations are text (``fleetlink.common.durations``) and
names have one type each (``fleetlink.common.names``). ``load_config`` reads the file, applies
``--set`` overrides (:mod:`.overrides`), validates it and, on failure, raises a ``ConfigError``
listing every problem as
``path.to[0].field (line N): message``. No socket is opened.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

from fleetlink.common.errors import ConfigError
from fleetlink.common.overrides import Override, apply_overrides
from fleetlink.common.yaml_paths import PathPart, format_path

__all__ = [
    "PathPart",
    "Places",
    "Problem",
    "Section",
    "format_path",
    "load_config",
    "problems_error",
    "read_config",
    "read_yaml",
    "validate_data",
    "validation_problems",
]

ModelT = TypeVar("ModelT", bound=BaseModel)


class Section(BaseModel):
    """The base of every config model and section: a key it does not declare is an error (a
    misspelt key would otherwise leave its default in force without a word). A subclass's own
    ``model_config`` adds to this one."""

    model_config = ConfigDict(extra="forbid")


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


@dataclass(frozen=True)
class Places:
    """Where the values of a config came from: lines of its file, and the overrides applied."""

    lines: Mapping[tuple[PathPart, ...], int] = field(default_factory=dict)
    overridden: Mapping[tuple[PathPart, ...], str] = field(default_factory=dict)
    """YAML path -> the override that set it (``--set``, ``$FLEETLINK_SET``)."""

    def describe(self, loc: tuple[PathPart, ...]) -> str:
        """`` (line 12)``, `` (set by --set)`` or nothing."""
        for end in range(len(loc), 0, -1):
            source = self.overridden.get(loc[:end])
            if source is not None:
                return f" (set by {source})"
        for end in range(len(loc), 0, -1):
            line = self.lines.get(loc[:end])
            if line is not None:
                return f" (line {line})"
        return ""


Problem = tuple[tuple[PathPart, ...], str]
"""A YAML path and what is wrong there."""


def problems_error(source: str, problems: Sequence[Problem], places: Places | None = None) -> ConfigError:
    """One ``ConfigError`` listing every problem as ``path (line N): message``."""
    places = places or Places()
    listing = "\n  ".join(f"{format_path(loc)}{places.describe(loc)}: {msg}" for loc, msg in problems)
    return ConfigError(f"{source}: {len(problems)} problem(s) in the config:\n  {listing}")


def validation_problems(exc: ValidationError) -> list[Problem]:
    """One problem per pydantic error, at its YAML path."""
    problems: list[Problem] = []
    for err in exc.errors(include_url=False):
        # pydantic puts the tag of a discriminated union / function validator in loc; drop non-keys
        loc = tuple(p for p in err["loc"] if isinstance(p, str | int))
        msg = err["msg"]
        if err["type"] == "extra_forbidden":
            msg = "unknown key (not allowed here; check the spelling)"
        problems.append((loc, msg))
    return problems


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


def validate_data(model: type[ModelT], data: Any, *, source: str, places: Places | None = None) -> ModelT:
    """Validate parsed data (None as an empty mapping) as ``model``.

    Raises one ``ConfigError`` from ``source`` listing every problem as ``path (line N): message``
    (lines and overrides come from ``places``).
    """
    if data is None:
        data = {}
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise problems_error(source, validation_problems(exc), places) from None


def read_config(path: Path, overrides: Sequence[Override] = ()) -> tuple[Any, Places]:
    """The file's data with the overrides applied, and where each value came from."""
    data, lines = read_yaml(path)
    if overrides:
        data = apply_overrides(data, overrides)
    return data, Places(lines, {o.path: o.source for o in overrides})


def load_config(model: type[ModelT], path: Path, overrides: Sequence[Override] = ()) -> ModelT:
    """Read ``path``, apply ``overrides`` and validate it as ``model``; raises ``ConfigError``
    naming each bad YAML path."""
    data, places = read_config(path, overrides)
    return validate_data(model, data, source=str(path), places=places)
