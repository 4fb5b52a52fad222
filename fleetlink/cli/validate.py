"""``fleetlink validate FILE``: check a fleetlink config as start-up would, without opening a socket.

The kind of config (edge, uplink, repeater) is told by ``--kind`` or guessed from its
top-level keys. Besides the keys and values, the checks of this machine run too (folders,
message packages, mapping types, Zenoh config files, secrets files: ``startup_checks``), so a
file that validates also starts; ``--no-host-checks`` leaves them out for a config meant for
another machine. Every problem is printed with its YAML path; the exit code is 0 when the file
is valid, 1 when it is not, 2 on usage errors.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pydantic import BaseModel

from fleetlink.cli.configs import KINDS, add_set_argument, guess_kind, load_service_config
from fleetlink.common.errors import ConfigError

__all__ = ["guess_kind", "register", "validate_file"]


def register(sub: Any) -> None:
    """Add ``fleetlink validate FILE`` to the subcommands."""
    parser: argparse.ArgumentParser = sub.add_parser(
        "validate",
        help="check a fleetlink config file (edge, uplink, repeater) as start-up would, without connecting",
        description="Validate a config file as start-up would (keys and values, then folders, message "
        "packages, mapping types, Zenoh config files on this machine); print each problem with "
        "its YAML path. Exit 0 if valid.",
    )
    parser.add_argument("file", type=Path, help="the YAML config file")
    parser.add_argument("--kind", choices=sorted(KINDS), help="config kind (default: guessed from keys)")
    add_set_argument(parser)
    parser.add_argument(
        "--no-host-checks",
        action="store_true",
        help="check keys and values only, not this machine's folders, packages and files "
        "(for a config meant for another machine)",
    )
    parser.set_defaults(handler=_validate)


def validate_file(
    path: Path, kind: str | None = None, sets: Sequence[str] = (), *, host_checks: bool = True
) -> tuple[str, BaseModel]:
    """Load and check the config at ``path`` as start-up would; returns its kind and model.

    Raises ``ConfigError`` listing every problem by its YAML path.
    """
    return load_service_config(path, sets, kind=kind, host_checks=host_checks)


def _validate(args: argparse.Namespace) -> int:
    try:
        kind, _config = validate_file(args.file, args.kind, args.set, host_checks=not args.no_host_checks)
    except ConfigError as exc:
        print(f"fleetlink: {exc}", file=sys.stderr)
        return 1
    checked = "keys and values" if args.no_host_checks else "start-up checks passed"
    print(f"{args.file}: valid {kind} config ({checked})")
    return 0
