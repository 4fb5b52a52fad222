"""``fleetlink repeater run -c repeater.yaml``: replay commands near the robots until stopped."""

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
from repeater.config import RepeaterConfig

log = logging.getLogger(__name__)


def register(sub: Any) -> None:
    parser: argparse.ArgumentParser = sub.add_parser(
        "repeater", help="near the robots: publish commands from Kafka as ROS messages under a lease",
        description="Run a repeater: take commands routed by the uplink, publish them as an rmw_zenoh "
        "publisher, repeat them every period until their lease ends, serve late joiners.",
    )
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    run = actions.add_parser("run", help="run the repeater until SIGINT/SIGTERM")
    run.add_argument("-c", "--config", type=Path, required=True, metavar="FILE", help="repeater YAML config")
    add_zenoh_arguments(run, ros=False)
    run.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    from repeater.service import Repeater

    config = load_config(RepeaterConfig, args.config)
    options = config.zenoh.merged_with(options_from_args(args))
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    with Repeater(config, options) as repeater:
        print(f"repeater {repeater.id} running for site {repeater.site}, state in "
              f"{config.repeater.state_dir}", flush=True)
        with contextlib.suppress(KeyboardInterrupt):
            stop.wait()
        log.info("stopping")
    return 0
