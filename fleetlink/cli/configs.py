"""A service's config as ``run`` and ``validate`` load it: the file, ``$FLEETLINK_SET`` and
``--set`` overrides on top, the model, then the start-up checks of this machine.

One path for both commands, so a config that validates also starts, and one that would not
start fails before anything is opened, each problem named by its YAML path.
"""

from __future__ import annotations

import argparse
import importlib
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel

from fleetlink.common.configfile import problems_error, read_config, validate_data
from fleetlink.common.errors import ConfigError
from fleetlink.common.overrides import ENV_VAR, collect_overrides

ModelT = TypeVar("ModelT", bound=BaseModel)

# kind -> (module, model class, top-level keys that identify it)
KINDS: dict[str, tuple[str, str, frozenset[str]]] = {
    "edge": ("fleetlink.edge.config", "EdgeConfig", frozenset({"site", "spool"})),
    "uplink": ("fleetlink.uplink.config", "UplinkConfig", frozenset({"kafka", "registry"})),
    "repeater": ("fleetlink.repeater.config", "RepeaterConfig", frozenset({"repeater"})),
}

SET_HELP = (
    "change one value of the config: KEY is its YAML path (spool.dir, zenoh.connect, "
    "mappings[0].to), VALUE is YAML (repeatable; also one KEY=VALUE per line in $" + ENV_VAR + ")"
)


def add_set_argument(parser: argparse.ArgumentParser) -> None:
    """Add the repeatable ``--set KEY=VALUE`` option to ``parser``."""
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help=SET_HELP)


def guess_kind(data: Any) -> str | None:
    """The kind of config (``edge``, ``uplink``, ``repeater``) whose top-level keys ``data`` has, or None."""
    if not isinstance(data, dict):
        return None
    keys = set(data)
    for kind, (_module, _model, marks) in KINDS.items():
        if marks <= keys:
            return kind
    return None


def model_for(kind: str) -> type[BaseModel]:
    """The config model of ``kind``; raises ``ConfigError`` when this install lacks that component."""
    module, name, _ = KINDS[kind]
    try:
        model: type[BaseModel] = getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError):
        raise ConfigError(f"this fleetlink has no {kind} component to validate against") from None
    return model


def load_service_config(
    path: Path,
    sets: Sequence[str] = (),
    *,
    kind: str | None = None,
    host_checks: bool = True,
    environ: Mapping[str, str] | None = None,
) -> tuple[str, BaseModel]:
    """The config at ``path`` with its overrides, validated; ``kind`` is guessed when not given."""
    from fleetlink.cli.startup_checks import CHECKS

    overrides = collect_overrides(os.environ if environ is None else environ, sets)
    data, places = read_config(path, overrides)
    kind = kind or guess_kind(data)
    if kind is None:
        hints = "; ".join(f"{k}: {', '.join(sorted(m))}" for k, (_a, _b, m) in KINDS.items())
        raise ConfigError(
            f"{path}: cannot tell which kind of config this is (top-level keys expected — {hints}); "
            "pass --kind"
        )
    config = validate_data(model_for(kind), data, source=str(path), places=places)
    if host_checks:
        problems = CHECKS[kind](config)
        if problems:
            raise problems_error(str(path), problems, places)
    return kind, config


def load_service(
    model: type[ModelT], kind: str, args: argparse.Namespace, *, host_checks: bool = True
) -> ModelT:
    """The config of ``fleetlink KIND run -c FILE --set ...`` (and of KIND's other actions)."""
    _kind, config = load_service_config(args.config, args.set, kind=kind, host_checks=host_checks)
    if not isinstance(config, model):
        raise ConfigError(f"{args.config}: not a {kind} config")
    return config
