"""``fleetlink validate FILE``: check any fleetlink config without opening a socket.

The kind of config (edge, uplink, repeater) is told by ``--kind`` or guessed from its
top-level keys. Every problem is printed with its YAML path; the exit code is 0 when the file
is valid, 1 when it is not, 2 on usage errors.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path
from typing import Any

from pydantic import BaseModel

from fleetlink.common.configfile import read_yaml, validate_data
from fleetlink.common.errors import ConfigError

# kind -> (module, model class, top-level keys that identify it)
KINDS: dict[str, tuple[str, str, frozenset[str]]] = {
    "edge": ("fleetlink.edge.config", "EdgeConfig", frozenset({"site", "spool"})),
    "uplink": ("fleetlink.uplink.config", "UplinkConfig", frozenset({"kafka", "registry"})),
    "repeater": ("fleetlink.repeater.config", "RepeaterConfig", frozenset({"repeater"})),
}


def register(sub: Any) -> None:
    parser: argparse.ArgumentParser = sub.add_parser(
        "validate",
        help="check a fleetlink config file (edge, uplink, repeater) without connecting",
        description="Validate a config file; print each problem with its YAML path. Exit 0 if valid.",
    )
    parser.add_argument("file", type=Path, help="the YAML config file")
    parser.add_argument("--kind", choices=sorted(KINDS), help="config kind (default: guessed from keys)")
    parser.set_defaults(handler=_validate)


def guess_kind(data: Any) -> str | None:
    if not isinstance(data, dict):
        return None
    keys = set(data)
    for kind, (_module, _model, marks) in KINDS.items():
        if marks <= keys:
            return kind
    return None


def model_for(kind: str) -> type[BaseModel]:
    module, name, _ = KINDS[kind]
    try:
        model: type[BaseModel] = getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError):
        raise ConfigError(f"this fleetlink has no {kind} component to validate against") from None
    return model


def validate_file(path: Path, kind: str | None = None) -> tuple[str, BaseModel]:
    data, lines = read_yaml(path)
    kind = kind or guess_kind(data)
    if kind is None:
        hints = "; ".join(f"{k}: {', '.join(sorted(m))}" for k, (_a, _b, m) in KINDS.items())
        raise ConfigError(
            f"{path}: cannot tell which kind of config this is (top-level keys expected — "
            f"{hints}); pass --kind"
        )
    return kind, validate_data(model_for(kind), data, source=str(path), lines=lines)


def _validate(args: argparse.Namespace) -> int:
    try:
        kind, _config = validate_file(args.file, args.kind)
    except ConfigError as exc:
        print(f"fleetlink: {exc}", file=sys.stderr)
        return 1
    print(f"{args.file}: valid {kind} config")
    return 0
