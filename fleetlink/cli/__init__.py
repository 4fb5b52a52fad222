"""The ``fleetlink`` command: one entry point, one subcommand per component.

Each component contributes its subcommands through a module exposing
``register(subparsers)``; the subcommand's handler returns the process exit code.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Callable, Sequence

from fleetlink import __version__
from fleetlink.cli.logs import configure_logging
from fleetlink.common.errors import FleetlinkError

# Modules that add subcommands, in the order they appear in --help.
COMMAND_MODULES: tuple[str, ...] = (
    "fleetlink.demo.cli",
    "fleetlink.cli.validate",
    "fleetlink.cli.stack",
    "fleetlink.cli.kafka",
    "fleetlink.cli.ros",
    "fleetlink.cli.schemas",
    "fleetlink.cli.certs",
    "fleetlink.cli.routers",
    "fleetlink.cli.edge",
    "fleetlink.cli.spool",
    "fleetlink.cli.uplink",
    "fleetlink.cli.repeater",
    "fleetlink.cli.probe",
    "fleetlink.cli.console",
)

Handler = Callable[[argparse.Namespace], int]


def build_parser() -> argparse.ArgumentParser:
    """The ``fleetlink`` argument parser with the global options and every module's subcommands."""
    parser = argparse.ArgumentParser(
        prog="fleetlink",
        description="Connect fleets of ROS 2 robots (rmw_zenoh) to Apache Kafka.",
    )
    parser.add_argument("--version", action="version", version=f"fleetlink {__version__}")
    parser.add_argument(
        "-v",
        "--verbose",
        action="count",
        default=0,
        help="more log output: -v info, -vv debug (services log info by default)",
    )
    parser.add_argument(
        "--log-format",
        choices=["text", "json"],
        default="text",
        help="log lines as text (default) or one JSON object per line (for log collectors)",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``fleetlink`` command line; returns the exit code.

    2 when no subcommand was given, 1 for a ``FleetlinkError`` (printed), 130 on Ctrl-C and 141
    when the reader of standard output went away; else the subcommand's own code.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    handler: Handler | None = getattr(args, "handler", None)
    if handler is None:
        parser.print_help()
        return 2
    configure_logging(args.verbose + getattr(args, "log_verbosity", 0), args.log_format)
    try:
        return handler(args)
    except FleetlinkError as exc:
        print(f"fleetlink: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # the reader went away (`fleetlink ros echo ... | head`)
        sys.stderr.close()
        return 141


if __name__ == "__main__":
    sys.exit(main())
