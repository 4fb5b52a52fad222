"""``fleetlink repeater run -c repeater.yaml``: replay commands near the robots until stopped."""

from __future__ import annotations

import argparse
from typing import Any

from fleetlink.cli.configs import load_service
from fleetlink.cli.service import add_service_command, wait_for_stop
from fleetlink.common.zenoh_options import options_from_args
from fleetlink.repeater.config import RepeaterConfig


def register(sub: Any) -> None:
    """Add ``fleetlink repeater run`` to the subcommands."""
    add_service_command(
        sub,
        "repeater",
        help_text="near the robots: publish commands from Kafka as ROS messages under a lease",
        description="Run a repeater: take commands routed by the uplink, publish them as an rmw_zenoh "
        "publisher, repeat them every period until their lease ends, serve late joiners.",
        handler=_run,
    )


def _run(args: argparse.Namespace) -> int:
    from fleetlink.repeater.service import Repeater

    config = load_service(RepeaterConfig, "repeater", args)
    with Repeater(config, config.zenoh.merged_with(options_from_args(args))) as repeater:
        print(
            f"repeater {repeater.id} running for site {repeater.site}, state in {config.repeater.state_dir}",
            flush=True,
        )
        wait_for_stop()
    return 0
