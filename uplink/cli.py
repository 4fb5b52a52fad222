"""``fleetlink uplink run -c uplink.yaml``: serve edge batches and commands until stopped."""

from __future__ import annotations

import argparse
import contextlib
import logging
import signal
import threading
from pathlib import Path
from typing import Any

from fleetlink.configfile import load_config
from fleetlink.zenoh_options import add_zenoh_arguments, options_from_args
from uplink.config import UplinkConfig

log = logging.getLogger(__name__)


def register(sub: Any) -> None:
    parser: argparse.ArgumentParser = sub.add_parser(
        "uplink", help="the cloud side: edge batches → Kafka (Avro), commands → sites",
        description="Run the uplink: receive batches from edge agents over Zenoh and produce them to "
        "Kafka with acks=all; answer each batch once Kafka acknowledged every record.",
    )
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    run = actions.add_parser("run", help="run the uplink until SIGINT/SIGTERM")
    run.add_argument("-c", "--config", type=Path, required=True, metavar="FILE", help="uplink YAML config")
    add_zenoh_arguments(run, ros=False)
    run.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    from uplink.service import Uplink

    config = load_config(UplinkConfig, args.config)
    options = config.zenoh.merged_with(options_from_args(args))
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    with Uplink(config, options):
        print(f"uplink running: Kafka {config.kafka.bootstrap_servers}, registry {config.registry.url}",
              flush=True)
        with contextlib.suppress(KeyboardInterrupt):
            stop.wait()
        log.info("stopping")
    return 0
