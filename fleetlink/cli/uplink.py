"""``fleetlink uplink run -c uplink.yaml``: serve edge batches and commands until stopped."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from typing import Any

from fleetlink.cli.configs import load_service
from fleetlink.cli.service import add_service_command, wait_for_stop
from fleetlink.common.errors import ConfigError
from fleetlink.common.extras import MissingExtraError
from fleetlink.common.zenoh_options import options_from_args
from fleetlink.uplink.config import UplinkConfig


def register(sub: Any) -> None:
    add_service_command(
        sub,
        "uplink",
        help_text="the cloud side: edge batches → Kafka (Avro), commands → sites",
        description="Run the uplink: receive batches from edge agents over Zenoh and produce them to "
        "Kafka with acks=all; answer each batch once Kafka acknowledged every record.",
        handler=_run,
    )


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
