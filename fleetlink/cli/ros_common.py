"""What the ``fleetlink ros`` commands share: the type-store options and where they lead."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import TYPE_CHECKING

from fleetlink.common.errors import ConfigError

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

DISTROS = ("humble", "jazzy", "kilted")
MSG_PATH_ENV = "FLEETLINK_MSG_PATH"


def add_types_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--distro`` and the repeatable ``--msg-path`` to ``parser``."""
    parser.add_argument(
        "--distro",
        choices=DISTROS,
        default="jazzy",
        help="ROS 2 distro whose type hashes to use (default jazzy)",
    )
    parser.add_argument(
        "--msg-path",
        action="append",
        type=Path,
        default=[],
        metavar="DIR",
        help="a package folder with msg/, srv/ or action/ files, for types fleetlink does not ship "
        f"(repeatable; also ${MSG_PATH_ENV}, folders separated by '{os.pathsep}')",
    )


def msg_paths(args: argparse.Namespace) -> list[Path]:
    """The ``--msg-path`` folders, then those of the environment; ``ConfigError`` for a non-folder."""
    paths = list(args.msg_path)
    env = os.environ.get(MSG_PATH_ENV, "")
    paths += [Path(p) for p in env.split(os.pathsep) if p]
    for path in paths:
        if not path.is_dir():
            raise ConfigError(f"--msg-path {path}: not a directory")
    return paths


def typestore(args: argparse.Namespace) -> Typestore:
    """The distro's types, the bundled packages and ``--msg-path`` packages."""
    from fleetlink.schemas.typestore import load_typestore

    return load_typestore(args.distro, msg_paths(args))
