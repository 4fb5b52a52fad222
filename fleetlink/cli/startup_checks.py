"""What a service checks on this machine before it opens anything, beyond its config's model.

``fleetlink validate`` and ``fleetlink edge|uplink|repeater run`` run the same checks, so a config
that validates also starts: folders exist or can be made by this user, message packages load,
every mapping's ROS type is known, Zenoh config files are concrete and Zenoh's own parser takes
them, files the config names (secrets, certificates, command signing keys) are there. Each
problem carries the YAML path it is about. No socket is opened.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fleetlink.common.configfile import PathPart, Problem
from fleetlink.common.errors import ConfigError
from fleetlink.common.zenoh_options import ZenohSection, zenoh_file_problem
from fleetlink.schemas.errors import SchemaError
from fleetlink.schemas.typestore import Distro, load_typestore

if TYPE_CHECKING:
    from fleetlink.edge.config import EdgeConfig, MappingConfig
    from fleetlink.repeater.config import RepeaterConfig
    from fleetlink.uplink.config import UplinkConfig

Check = Callable[[Any], list[Problem]]


def writable_dir_problem(path: Path) -> str | None:
    """Why this user cannot use ``path`` as a folder (creating it if missing), or None."""
    if path.exists():
        if not path.is_dir():
            return f"{path} exists and is not a folder"
        if not os.access(path, os.W_OK | os.X_OK):
            return f"{path} is not writable by this user"
        return None
    parent = path.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        return f"{path} does not exist and this user cannot create it ({parent} is not writable)"
    return None


def zenoh_problems(section: ZenohSection, at: tuple[PathPart, ...] = ("zenoh",)) -> list[Problem]:
    """Problems of a ``zenoh:`` section: a config file Zenoh would refuse, or options it rejects."""
    if section.config_file is not None:
        problem = zenoh_file_problem(section.config_file)
        if problem is not None:
            return [((*at, "config_file"), problem)]
    try:
        section.options().to_config()
    except ConfigError as exc:
        return [(at, str(exc))]
    return []


def message_path_problems(
    distro: Distro, paths: Sequence[Path], at: tuple[PathPart, ...] = ("ros", "message_paths")
) -> tuple[list[Problem], Any]:
    """Problems of ``ros.message_paths``, and the type store they make (None if they fail)."""
    missing = [((*at, i), f"{p} is not a folder") for i, p in enumerate(paths) if not Path(p).is_dir()]
    if missing:
        return list(missing), None
    try:
        return [], load_typestore(distro, paths)
    except SchemaError as exc:
        return [(at, f"cannot load the message packages: {exc}")], None


def file_problems(files: Sequence[tuple[tuple[PathPart, ...], Path | None]], hint: str = "") -> list[Problem]:
    """A problem for each named file that is not a readable file (``hint`` is appended)."""
    return [
        (at, f"{path} is not a readable file{hint}")
        for at, path in files
        if path is not None and not (path.is_file() and os.access(path, os.R_OK))
    ]


KEY_HINT = " (make the key pair with `fleetlink certs command-key DIR`)"


def edge_problems(config: EdgeConfig) -> list[Problem]:
    """The edge's start-up problems: Zenoh, message packages, unknown mapping types, the spool folder."""
    from fleetlink.edge.runtime.types import schema_distro

    problems = zenoh_problems(config.zenoh)
    type_problems, ts = message_path_problems(schema_distro(config.ros.distro), config.ros.message_paths)
    problems += type_problems
    if ts is not None:
        declared: list[tuple[tuple[PathPart, ...], MappingConfig]] = [
            (("mappings", i), m) for i, m in enumerate(config.mappings)
        ]
        declared += [
            (("robot_types", name, "mappings", i), m)
            for name, rt in config.robot_types.items()
            for i, m in enumerate(rt.mappings)
        ]
        problems += [
            (
                (*at, "type"),
                f"unknown ROS type {m.type!r}: not a {config.ros.distro} type, not in the bundled "
                "packages, not in ros.message_paths",
            )
            for at, m in declared
            if m.type is not None and m.type not in ts.fielddefs
        ]
    spool = writable_dir_problem(Path(config.spool.dir))
    if spool is not None:
        problems.append((("spool", "dir"), spool))
    return problems


def uplink_problems(config: UplinkConfig) -> list[Problem]:
    """The uplink's start-up problems: Zenoh and the files it names (Kafka secrets, token, signing key)."""
    problems = zenoh_problems(config.zenoh)
    kafka = config.kafka
    files: list[tuple[tuple[PathPart, ...], Path | None]] = []
    if kafka.sasl is not None:
        files.append((("kafka", "sasl", "password_file"), kafka.sasl.password_file))
    if kafka.ssl is not None:
        files += [
            (("kafka", "ssl", name), getattr(kafka.ssl, name))
            for name in ("ca_location", "certificate_location", "key_location")
        ]
    if config.console is not None:
        files.append((("console", "token_file"), config.console.token_file))
    problems += file_problems(files)
    if config.command_signing is not None:
        key = [(("command_signing", "key_file"), config.command_signing.key_file)]
        problems += file_problems(key, KEY_HINT)
    return problems


def repeater_problems(config: RepeaterConfig) -> list[Problem]:
    """The repeater's start-up problems: Zenoh, message packages, its state folder, command keys."""
    problems = zenoh_problems(config.zenoh)
    problems += message_path_problems(config.ros.distro, config.ros.message_paths)[0]
    state = writable_dir_problem(Path(config.repeater.state_dir))
    if state is not None:
        problems.append((("repeater", "state_dir"), state))
    keys = [(("repeater", "command_keys", i), path) for i, path in enumerate(config.repeater.command_keys)]
    return problems + file_problems(keys, KEY_HINT)


CHECKS: dict[str, Check] = {"edge": edge_problems, "uplink": uplink_problems, "repeater": repeater_problems}
