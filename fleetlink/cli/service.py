"""What ``fleetlink uplink run`` and ``fleetlink repeater run`` share: the parser, the wait for a stop."""

from __future__ import annotations

import argparse
import contextlib
import logging
import signal
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fleetlink.cli.configs import add_set_argument
from fleetlink.cli.logs import SERVICE_VERBOSITY
from fleetlink.common.zenoh_options import add_zenoh_arguments

log = logging.getLogger(__name__)


def add_service_command(
    sub: Any,
    name: str,
    *,
    help_text: str,
    description: str,
    handler: Callable[[argparse.Namespace], int],
    more: Callable[[Any], None] | None = None,
) -> argparse.ArgumentParser:
    """``fleetlink NAME run -c FILE [zenoh options]``; returns the ``run`` parser. ``more`` may
    add other actions to the command's subparsers."""
    parser: argparse.ArgumentParser = sub.add_parser(name, help=help_text, description=description)
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    run = actions.add_parser("run", help=f"run the {name} until SIGINT/SIGTERM")
    run.add_argument("-c", "--config", type=Path, required=True, metavar="FILE", help=f"{name} YAML config")
    add_set_argument(run)
    add_zenoh_arguments(run, ros=False)
    run.set_defaults(handler=handler, log_verbosity=SERVICE_VERBOSITY)
    if more is not None:
        more(actions)
    return run


def wait_for_stop() -> None:
    """Block until SIGTERM or Ctrl-C (SIGINT)."""
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        with contextlib.suppress(KeyboardInterrupt):
            stop.wait()
    finally:
        signal.signal(signal.SIGTERM, previous)
    log.info("stopping")
