"""Command line: ``python -m fleetlink.examples.fault_detection --bootstrap HOST:PORT --registry URL ...``."""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

from pydantic import ValidationError

from fleetlink.common.errors import FleetlinkError
from fleetlink.examples.fault_detection.errors import FaultDetectionError
from fleetlink.examples.fault_detection.settings import (
    DEFAULT_STATE_DIR,
    FaultDetectionSettings,
    Topics,
    parse_duration_ms,
)

__all__ = ["build_parser", "main", "settings_from_args"]

logger = logging.getLogger(__name__)


def _duration(text: str) -> int:
    try:
        return parse_duration_ms(text)
    except FaultDetectionError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def _hazards(text: str) -> frozenset[int]:
    try:
        return frozenset(int(part) for part in text.split(",") if part.strip())
    except ValueError as exc:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated hazard type numbers, got {text!r}"
        ) from exc


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the fault-detection app: Kafka, registry, window, rule and topic options."""
    defaults = Topics()
    parser = argparse.ArgumentParser(
        prog="python -m fleetlink.examples.fault_detection",
        description="Fault detection over the fleet's sensor topics: a sliding window per robot; when "
        "every event in it says failure the robot is failed (red light ring), when every event says "
        "healthy it runs again (green). One command per change of state.",
    )
    parser.add_argument("--bootstrap", required=True, metavar="HOST:PORT", help="Kafka bootstrap servers")
    parser.add_argument("--registry", required=True, metavar="URL", help="schema registry URL")
    parser.add_argument(
        "--window",
        type=_duration,
        default=2000,
        metavar="DURATION",
        help="sliding window length, e.g. 2s, 500ms (default: 2s)",
    )
    parser.add_argument(
        "--grace",
        type=_duration,
        default=1000,
        metavar="DURATION",
        help="how late a record may arrive and still count (default: 1s)",
    )
    parser.add_argument(
        "--group", default="fleetlink-fault-detection", help="consumer group (default: %(default)s)"
    )
    parser.add_argument(
        "--state-dir", type=Path, default=DEFAULT_STATE_DIR, help="state store folder (default: %(default)s)"
    )
    parser.add_argument(
        "--msg-path",
        type=Path,
        action="append",
        default=[],
        metavar="DIR",
        help="ROS package folder to read irobot_create_msgs from (repeatable; default: the copy "
        "fleetlink ships)",
    )
    parser.add_argument(
        "--distro",
        choices=("humble", "jazzy", "kilted"),
        default="jazzy",
        help="ROS 2 distro of the robots (default: %(default)s)",
    )
    parser.add_argument(
        "--from-beginning",
        action="store_true",
        help="a new consumer group starts at the earliest records (default: the latest)",
    )
    parser.add_argument(
        "--ir-threshold",
        type=int,
        default=3000,
        help="IR readings all above this mean the robot is picked up (default: %(default)s)",
    )
    parser.add_argument(
        "--failure-hazards",
        type=_hazards,
        default=frozenset({2, 4}),
        metavar="N[,N...]",
        help="HazardDetection types that mean failure (default: 2,4 = CLIFF, WHEEL_DROP)",
    )
    parser.add_argument(
        "--min-events",
        type=int,
        default=2,
        help="fewer events than this in a window never change the state (default: %(default)s)",
    )
    parser.add_argument("--ir-topic", default=defaults.ir_intensity)
    parser.add_argument("--hazard-topic", default=defaults.hazard_detection)
    parser.add_argument("--kidnap-topic", default=defaults.kidnap_status)
    parser.add_argument("--commands-topic", default=defaults.commands)
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    return parser


def settings_from_args(args: argparse.Namespace) -> FaultDetectionSettings:
    """The settings the parsed options describe; pydantic validates them."""
    return FaultDetectionSettings(
        bootstrap=args.bootstrap,
        registry_url=args.registry,
        window=args.window / 1000,
        grace=args.grace / 1000,
        group=args.group,
        state_dir=args.state_dir,
        offset_reset="earliest" if args.from_beginning else "latest",
        ir_threshold=args.ir_threshold,
        failure_hazards=args.failure_hazards,
        min_events=args.min_events,
        distro=args.distro,
        msg_paths=tuple(args.msg_path),
        topics=Topics(
            ir_intensity=args.ir_topic,
            hazard_detection=args.hazard_topic,
            kidnap_status=args.kidnap_topic,
            commands=args.commands_topic,
        ),
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Run the fault-detection app from command-line options until SIGINT or SIGTERM.

    Returns 0 after a clean stop, 1 on a ``FleetlinkError`` and 2 for invalid options.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.WARNING - 10 * min(args.verbose + 1, 2),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        settings = settings_from_args(args)
    except ValidationError as exc:
        print(f"invalid options:\n{exc}", file=sys.stderr)
        return 2
    from fleetlink.examples.fault_detection.app import run

    try:
        run(settings)  # SIGINT / SIGTERM stop it cleanly
    except FleetlinkError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0
