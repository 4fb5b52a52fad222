"""``fleetlink demo``: the warehouse fault-detection loop, one command, on this machine."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from fleetlink.common.extras import MissingExtraError


def register(sub: Any) -> None:
    """Add the ``demo`` command and its options to the ``fleetlink`` subcommands ``sub``."""
    parser: argparse.ArgumentParser = sub.add_parser(
        "demo",
        help="run the warehouse demo: robots → Kafka → fault detection → light-ring commands",
        description="Start Kafka, the registry, Zenoh routers, the uplink, an edge agent, a repeater, "
        "a fault-detection app and simulated TurtleBot 4 robots; pick one robot up and put it down; "
        "show its light ring turn red and green. Ctrl-C stops everything it started.",
    )
    parser.add_argument("--robots", type=int, default=3, help="robots at start (default %(default)s)")
    parser.add_argument("--rate", type=float, default=10.0, help="sensor rate in Hz (default %(default)s)")
    parser.add_argument("--window", default="2s", help="fault-detection window (default %(default)s)")
    parser.add_argument(
        "--app",
        choices=("python", "java"),
        default="python",
        help="the fault-detection app: python (Quix Streams, examples/fault_detection) or java (Kafka "
        "Streams, examples/kafka-streams-fault-detection, built with Maven on first use; "
        "default %(default)s)",
    )
    parser.add_argument(
        "--workdir",
        type=Path,
        default=Path("var/demo"),
        help="logs, configs, spool, summary.json (default %(default)s; wiped at start)",
    )
    parser.add_argument("--bootstrap", help="use this Kafka instead of starting one (with --registry)")
    parser.add_argument("--registry", help="use this schema registry (Confluent API URL)")
    parser.add_argument(
        "--keep-running",
        action="store_true",
        help="after the scenario, keep everything running until Ctrl-C (or --duration)",
    )
    parser.add_argument("--duration", type=float, help="with --keep-running: stop after this many seconds")
    parser.set_defaults(handler=_run)


def missing_parts() -> str | None:
    """Why this install cannot run the demo (its stream app and the console are extras), or None."""
    try:
        import fleetlink.console.app
        import fleetlink.examples.fault_detection.app  # noqa: F401 - imported to see that it can be
    except MissingExtraError as exc:
        return f"the demo needs its extra, pip install 'fleetlink[demo]' ({exc.package} is not installed)"
    return None


def _run(args: argparse.Namespace) -> int:
    from fleetlink.demo.runner import Demo, DemoOptions, interrupted_on_sigint

    missing = missing_parts()
    if missing is not None:
        print(f"fleetlink demo: {missing}")
        return 2
    if args.robots < 2:
        print("fleetlink demo: --robots must be at least 2 (one to fault, one to stay healthy)")
        return 2
    if bool(args.bootstrap) != bool(args.registry):
        print("fleetlink demo: give both --bootstrap and --registry, or neither")
        return 2
    demo = Demo(
        DemoOptions(
            workdir=args.workdir,
            robots=args.robots,
            rate_hz=args.rate,
            window=args.window,
            bootstrap=args.bootstrap,
            registry_url=args.registry,
            keep_running=args.keep_running,
            duration_s=args.duration,
            app=args.app,
        )
    )
    with interrupted_on_sigint(demo):
        summary = demo.run()
    return 0 if summary["loop_closed"] else 1
