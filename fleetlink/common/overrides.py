"""``--set KEY=VALUE`` and ``$FLEETLINK_SET``: change single values of a YAML config at start-up.

A key is the YAML path of the value, as errors print it: ``spool.dir``, ``zenoh.connect``,
``robot_types.turtlebot4.mappings[0].to``; a key holding a dot is quoted:
``kafka.producer_overrides."batch.size"``. The value is read as YAML, so
``zenoh.connect=[tcp/10.0.0.5:7447]`` is a list and ``ros.domain_id=7`` a number. Missing
mappings on the way are created; a list index may name an existing item or the next one.

``FLEETLINK_SET`` holds overrides for containers and units, one ``KEY=VALUE`` per line (blank
lines and lines starting with ``#`` are skipped). The file comes first, then
``FLEETLINK_SET``, then ``--set`` options, in order. Pure: no file or environment access here.
"""

from __future__ import annotations

import copy
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import yaml

from fleetlink.common.errors import ConfigError
from fleetlink.common.yaml_paths import PathPart, format_path, parse_path

ENV_VAR = "FLEETLINK_SET"


@dataclass(frozen=True)
class Override:
    """One ``KEY=VALUE``: where it came from (``--set``, ``$FLEETLINK_SET``) and what it says."""

    path: tuple[PathPart, ...]
    value: Any
    text: str
    source: str

    def fail(self, why: str) -> ConfigError:
        """A ``ConfigError`` naming this override's source and text, saying ``why`` it cannot apply."""
        return ConfigError(f"{self.source} {self.text!r}: {why}")


def parse_override(text: str, source: str = "--set") -> Override:
    """Parse one ``KEY=VALUE`` (the value as YAML) from ``source``; raises ``ConfigError`` when malformed."""
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise ConfigError(f"{source} {text!r}: expected KEY=VALUE, e.g. spool.dir=/var/lib/fleetlink/spool")
    try:
        path = parse_path(key)
    except ValueError as exc:
        raise ConfigError(f"{source} {text!r}: {exc}") from None
    try:
        value = yaml.safe_load(raw) if raw.strip() else ""
    except yaml.YAMLError as exc:
        raise ConfigError(f"{source} {text!r}: the value is not valid YAML: {exc}") from None
    return Override(path, value, text, source)


def overrides_from_env(environ: Mapping[str, str]) -> list[Override]:
    """The overrides in ``$FLEETLINK_SET`` (one ``KEY=VALUE`` per line)."""
    lines = environ.get(ENV_VAR, "").splitlines()
    return [
        parse_override(line.strip(), f"${ENV_VAR}")
        for line in lines
        if line.strip() and not line.strip().startswith("#")
    ]


def collect_overrides(environ: Mapping[str, str], options: Iterable[str]) -> list[Override]:
    """``$FLEETLINK_SET`` first, then the ``--set`` options (later ones win)."""
    return [*overrides_from_env(environ), *(parse_override(o) for o in options)]


def apply_overrides(data: Any, overrides: Sequence[Override]) -> Any:
    """A copy of ``data`` (parsed YAML) with every override applied in order."""
    result = copy.deepcopy(data) if data is not None else {}
    for override in overrides:
        result = _apply(result, override)
    return result


def _apply(root: Any, override: Override) -> Any:
    if not isinstance(root, dict):
        raise override.fail("the config file's top level is not a mapping")
    path = override.path
    parent: Any = root
    for depth, part in enumerate(path[:-1]):
        child = _get(parent, part, path[:depth], override)
        if child is None:  # created on the way: a list when an index follows, else a mapping
            child = [] if isinstance(path[depth + 1], int) else {}
            _put(parent, part, child, path[:depth], override)
        parent = child
    _put(parent, path[-1], override.value, path[:-1], override)
    return root


def _container(node: Any, part: PathPart, at: tuple[PathPart, ...], override: Override) -> None:
    where = format_path(at) if at else "the top level"
    if isinstance(part, int) and not isinstance(node, list):
        raise override.fail(f"{where} is not a list, so [{part}] names nothing")
    if isinstance(part, str) and not isinstance(node, dict):
        raise override.fail(f"{where} is not a mapping, so it has no key {part!r}")
    if isinstance(part, int) and part > len(node):
        raise override.fail(f"{where} has {len(node)} item(s): [{part}] is past the next one")


def _get(node: Any, part: PathPart, at: tuple[PathPart, ...], override: Override) -> Any:
    _container(node, part, at, override)
    if isinstance(node, list):
        return node[part] if isinstance(part, int) and part < len(node) else None
    return node.get(part)


def _put(node: Any, part: PathPart, value: Any, at: tuple[PathPart, ...], override: Override) -> None:
    _container(node, part, at, override)
    if isinstance(node, list) and isinstance(part, int):
        if part == len(node):
            node.append(value)
        else:
            node[part] = value
    else:
        node[part] = value
