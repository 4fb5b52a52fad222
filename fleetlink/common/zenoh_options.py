"""Zenoh's usual command-line options, shared by every command that opens a session.

``-e/--connect``, ``-l/--listen``, ``-m/--mode``, ``--zenoh-config FILE`` and
``--cfg KEY:JSON5`` overrides, as in the zenoh examples; plus ``--domain-id`` for ROS 2.
A ``ZenohOptions`` value is plain data; ``to_config`` builds the ``zenoh.Config`` only when
a session is about to be opened.
"""

from __future__ import annotations

import argparse
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import zenoh

from fleetlink.common.configfile import Section
from fleetlink.common.errors import ConfigError
from fleetlink.common.zenoh_configs import placeholders

Mode = Literal["peer", "client", "router"]


@dataclass(frozen=True)
class ZenohOptions:
    """How to open a Zenoh session: mode, endpoints, a JSON5 file and ``KEY: JSON5`` overrides."""

    mode: Mode | None = None
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    config_file: Path | None = None
    overrides: tuple[tuple[str, str], ...] = ()
    multicast_scouting: bool = False
    extra: dict[str, str] = field(default_factory=dict)

    def to_config(self) -> zenoh.Config:
        """Build the session config: the JSON5 file first, then explicit options on top."""
        if self.config_file is not None:
            conf = load_zenoh_file(self.config_file)
        else:
            conf = zenoh.Config()
            conf.insert_json5("scouting/multicast/enabled", json.dumps(self.multicast_scouting))
        settings: list[tuple[str, str]] = []
        if self.mode is not None:
            settings.append(("mode", json.dumps(self.mode)))
        if self.connect:
            settings.append(("connect/endpoints", json.dumps(list(self.connect))))
        if self.listen:
            settings.append(("listen/endpoints", json.dumps(list(self.listen))))
        settings.extend(self.overrides)
        settings.extend(self.extra.items())
        for key, value in settings:
            try:
                conf.insert_json5(key, value)
            except zenoh.ZError as exc:
                raise ConfigError(f"zenoh option {key}={value}: {exc}") from None
        return conf

    def with_defaults(
        self, *, mode: Mode, connect: tuple[str, ...] = (), listen: tuple[str, ...] = ()
    ) -> ZenohOptions:
        """Fill in what the user did not say (the file or flags always win)."""
        if self.config_file is not None:
            return self
        return ZenohOptions(
            mode=self.mode or mode,
            connect=self.connect or connect,
            listen=self.listen or listen,
            config_file=None,
            overrides=self.overrides,
            multicast_scouting=self.multicast_scouting,
            extra=dict(self.extra),
        )


def zenoh_file_problem(path: Path) -> str | None:
    """Why Zenoh would refuse the config file at ``path``, or None: missing, a template with
    ``${...}`` placeholders left in it, or rejected by Zenoh's own parser."""
    try:
        load_zenoh_file(path)
    except ConfigError as exc:
        return str(exc)
    return None


def load_zenoh_file(path: Path) -> zenoh.Config:
    """A Zenoh config file parsed by Zenoh; a template that was not rendered is refused by name."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"zenoh config file not found: {path}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"zenoh config file {path}: cannot read it: {exc}") from None
    names = placeholders(text)
    if names:
        listed = ", ".join(f"${{{n}}}" for n in sorted(names))
        raise ConfigError(
            f"zenoh config file {path} is a template: {listed} have no value; write a concrete "
            f"config with `fleetlink zenoh render {path} ... -o FILE` and use that"
        )
    try:
        return zenoh.Config.from_file(str(path))
    except zenoh.ZError as exc:
        raise ConfigError(f"zenoh config file {path}: Zenoh refuses it: {exc}") from None


def add_zenoh_arguments(parser: argparse.ArgumentParser, *, ros: bool = True) -> None:
    """Add the Zenoh session options to ``parser``, and ``--domain-id`` unless ``ros`` is False."""
    group = parser.add_argument_group("zenoh session")
    group.add_argument("-m", "--mode", choices=["peer", "client", "router"], help="zenoh session mode")
    group.add_argument(
        "-e",
        "--connect",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)",
    )
    group.add_argument(
        "-l",
        "--listen",
        action="append",
        default=[],
        metavar="ENDPOINT",
        help="endpoint to listen on, e.g. tcp/127.0.0.1:7448 (repeatable)",
    )
    group.add_argument("--zenoh-config", type=Path, metavar="FILE", help="zenoh JSON5 config file")
    group.add_argument(
        "--cfg",
        action="append",
        default=[],
        metavar="KEY:JSON5",
        help="zenoh config override, e.g. 'scouting/multicast/enabled:true' (repeatable)",
    )
    if ros:
        group.add_argument(
            "--domain-id",
            type=int,
            default=default_domain_id(),
            metavar="N",
            help="ROS domain id (default: $ROS_DOMAIN_ID, else 0)",
        )


def default_domain_id() -> int:
    """The ROS domain id in ``$ROS_DOMAIN_ID`` (0 when unset); raises ``ConfigError`` when invalid."""
    raw = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if not raw:
        return 0
    try:
        value = int(raw)
    except ValueError:
        raise ConfigError(f"ROS_DOMAIN_ID={raw!r} is not an integer") from None
    if not 0 <= value <= 232:
        raise ConfigError(f"ROS_DOMAIN_ID={value} is out of range 0..232")
    return value


def options_from_args(args: argparse.Namespace) -> ZenohOptions:
    """The ``ZenohOptions`` given by parsed Zenoh arguments; raises ``ConfigError`` for a bad ``--cfg``."""
    overrides = []
    for item in args.cfg:
        key, sep, value = item.partition(":")
        if not sep or not key:
            raise ConfigError(f"--cfg {item!r}: expected KEY:JSON5_VALUE")
        overrides.append((key, value))
    return ZenohOptions(
        mode=args.mode,
        connect=tuple(args.connect),
        listen=tuple(args.listen),
        config_file=args.zenoh_config,
        overrides=tuple(overrides),
    )


class ZenohSection(Section):
    """The ``zenoh:`` section of a fleetlink config: a JSON5 file plus explicit overrides."""

    config_file: Path | None = None
    mode: Mode | None = None
    connect: list[str] = []
    listen: list[str] = []
    overrides: dict[str, Any] = {}

    def options(self) -> ZenohOptions:
        """The section as ``ZenohOptions`` (override values encoded as JSON)."""
        return ZenohOptions(
            mode=self.mode,
            connect=tuple(self.connect),
            listen=tuple(self.listen),
            config_file=self.config_file,
            overrides=tuple((k, json.dumps(v)) for k, v in self.overrides.items()),
        )

    def merged_with(self, cli: ZenohOptions) -> ZenohOptions:
        """Command-line options win over the file's section, field by field."""
        own = self.options()
        return ZenohOptions(
            mode=cli.mode or own.mode,
            connect=cli.connect or own.connect,
            listen=cli.listen or own.listen,
            config_file=cli.config_file or own.config_file,
            overrides=own.overrides + cli.overrides,
        )
