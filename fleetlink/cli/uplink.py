"""``fleetlink uplink run -c uplink.yaml``: serve edge batches and commands until stopped."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from fleetlink.cli.configs import add_set_argument, load_service
from fleetlink.cli.service import add_service_command, wait_for_stop
from fleetlink.common.errors import ConfigError
from fleetlink.common.extras import MissingExtraError
from fleetlink.common.zenoh_options import options_from_args
from fleetlink.uplink.config import UplinkConfig


def register(sub: Any) -> None:
    """Add ``fleetlink uplink run`` and ``fleetlink uplink release-robot`` to the subcommands."""
    add_service_command(
        sub,
        "uplink",
        help_text="the cloud side: edge batches → Kafka (Avro), commands → sites",
        description="Run the uplink: receive batches from edge agents over Zenoh and produce them to "
        "Kafka with acks=all; answer each batch once Kafka acknowledged every record.",
        handler=_run,
        more=_release_robot_action,
    )


def _release_robot_action(actions: Any) -> None:
    release = actions.add_parser(
        "release-robot",
        help="let a robot join another site now (a tombstone on the registrations topic)",
        description="Forget which site holds ROBOT: its registration is removed from the "
        "registrations topic, every uplink forgets the robot's site, and the next site to register "
        "it holds it (docs/security.md, robots are owned).",
    )
    release.add_argument("robot", help="the robot's name as registered")
    release.add_argument(
        "-c", "--config", type=Path, required=True, metavar="FILE", help="uplink YAML config"
    )
    add_set_argument(release)
    release.set_defaults(handler=_release_robot)


def _release_robot(args: argparse.Namespace) -> int:
    from fleetlink.uplink.release import release_robot

    config = load_service(UplinkConfig, "uplink", args, host_checks=False)  # only Kafka is needed
    release_robot(config, args.robot)
    print(f"released {args.robot}: any site may register it now", flush=True)
    return 0


def _run(args: argparse.Namespace) -> int:
    from fleetlink.uplink.service import Uplink, UplinkExtension

    config = load_service(UplinkConfig, "uplink", args)
    extensions: Sequence[Callable[[Uplink], UplinkExtension]] = ()
    if config.console is not None:
        try:
            from fleetlink.console.uplink import console_extensions
        except MissingExtraError as exc:
            raise ConfigError(f"{args.config}: console: {exc}") from None
        extensions = console_extensions(config)
    options = config.zenoh.merged_with(options_from_args(args))
    with Uplink(config, options, extensions=extensions):
        print(
            f"uplink running: Kafka {config.kafka.bootstrap_servers}, registry {config.registry.url}",
            flush=True,
        )
        wait_for_stop()
    return 0
