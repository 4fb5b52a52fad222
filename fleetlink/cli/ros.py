"""``fleetlink ros``: see, hear, speak to and simulate robots on the Zenoh network, as ``ros2`` does.

``graph`` (robots, nodes, topics, QoS, rates), ``echo`` and ``pub`` (``ros2 topic echo/pub``),
``sim`` (a simulated TurtleBot 4 fleet) and ``replay`` (a bag as a robot). Every command opens
its zenoh session from Zenoh's usual options (``-e/-l/-m/--zenoh-config``, ``--cfg``) plus
``--domain-id``; with no options it behaves like an rmw_zenoh node (peer, connecting to a router
on ``tcp/127.0.0.1:7447``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from fleetlink.cli.ros_call import register_calls
from fleetlink.cli.ros_common import add_types_arguments
from fleetlink.common.errors import ConfigError
from fleetlink.common.zenoh_options import add_zenoh_arguments, options_from_args


def register(sub: Any) -> None:
    """Add ``fleetlink ros`` (graph, echo, pub, call, action, sim, replay) to the subcommands."""
    from fleetlink.cli.ros_sim import replay_command, sim_command
    from fleetlink.cli.ros_topic import register_echo, register_pub

    ros = sub.add_parser(
        "ros",
        help="see, echo, publish, simulate or replay robots on the Zenoh network (like ros2)",
        description="ROS 2 over Zenoh without ROS 2: the graph, topics, simulated and replayed robots.",
    )
    ros_sub = ros.add_subparsers(dest="ros_command", metavar="COMMAND")
    ros.set_defaults(handler=lambda _args: _usage(ros))
    graph = ros_sub.add_parser("graph", help="robots, nodes, topics, types, QoS and rates")
    graph.add_argument("--json", action="store_true", help="print JSON instead of text")
    graph.add_argument(
        "--duration",
        type=float,
        default=2.0,
        metavar="S",
        help="how long to listen before reporting (default 2 s)",
    )
    graph.add_argument("--watch", type=float, metavar="S", help="report again every S seconds")
    graph.add_argument(
        "--count",
        type=int,
        default=0,
        metavar="N",
        help="with --watch: stop after N reports (default: until interrupted)",
    )
    graph.add_argument(
        "--robot-type",
        action="append",
        default=[],
        metavar="NAME=PATTERN",
        help="robot type by namespace pattern, e.g. turtlebot4=/tb4_* (repeatable; "
        "default: every top-level namespace is a robot)",
    )
    add_zenoh_arguments(graph)
    graph.set_defaults(handler=graph_command)

    register_echo(ros_sub)
    register_pub(ros_sub)
    register_calls(ros_sub, add_types_arguments)

    sim = ros_sub.add_parser("sim", help="run a simulated TurtleBot 4 fleet (iRobot Create 3 topics)")
    sim.add_argument("--robots", type=int, default=3, metavar="N", help="number of robots (default 3)")
    sim.add_argument("--prefix", default="tb4_", help="robot name prefix (default tb4_: tb4_01, tb4_02 …)")
    sim.add_argument("--rate", type=float, default=10.0, metavar="HZ", help="sensor rate (default 10 Hz)")
    sim.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    sim.add_argument(
        "--fault", action="append", default=[], metavar="ROBOT", help="start ROBOT picked up (repeatable)"
    )
    sim.add_argument(
        "--stdin",
        action="store_true",
        help="read commands from stdin: fault R, heal R, add [R], remove R, led R, list, quit",
    )
    add_types_arguments(sim)
    add_zenoh_arguments(sim)
    sim.set_defaults(handler=sim_command)

    replay = ros_sub.add_parser("replay", help="publish a rosbag2 recording as a robot would")
    replay.add_argument("bag", type=Path, help="rosbag2 directory or file (sqlite3 or MCAP)")
    replay.add_argument("--robot", required=True, help="robot name: topics are published under /NAME")
    replay.add_argument(
        "--rate",
        type=float,
        default=1.0,
        metavar="X",
        help="speed factor of the recorded timing (default 1; 0 = as fast as possible)",
    )
    replay.add_argument("--fast", action="store_true", help="as fast as possible (same as --rate 0)")
    replay.add_argument("--loop", action="store_true", help="start over at the end")
    replay.add_argument("--topic", action="append", metavar="TOPIC", help="only these bag topics")
    replay.add_argument(
        "--wait-subscribers",
        type=float,
        default=0.0,
        metavar="S",
        help="wait up to S seconds for a subscriber on every topic before starting",
    )
    add_types_arguments(replay)
    add_zenoh_arguments(replay)
    replay.set_defaults(handler=replay_command)


def _usage(parser: argparse.ArgumentParser) -> int:
    parser.print_help()
    return 2


def _robot_types(specs: list[str]) -> list[Any]:
    from fleetlink.roswire.robots import RobotType

    if not specs:
        return [RobotType("robot", "/*")]
    types = []
    for spec in specs:
        name, sep, pattern = spec.partition("=")
        if not sep or not name or not pattern:
            raise ConfigError(f"--robot-type {spec!r}: expected NAME=PATTERN such as turtlebot4=/tb4_*")
        types.append(RobotType(name, pattern))
    return types


# --- ros graph ------------------------------------------------------------------------------


def graph_command(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    """Print the ROS graph seen over Zenoh (text or JSON), once or every ``--watch`` seconds; returns 0."""
    from fleetlink.roswire.node import RosNode
    from fleetlink.roswire.report import RateMeter, graph_report, render_text
    from fleetlink.roswire.robot_watcher import RobotWatcher
    from fleetlink.roswire.session import ros_session_config

    types = _robot_types(args.robot_type)
    window = args.watch if args.watch else args.duration
    if window <= 0:
        raise ConfigError("--duration and --watch must be > 0 seconds")
    config = ros_session_config(options_from_args(args))
    meter = RateMeter()
    with RosNode("fleetlink_graph", domain_id=args.domain_id, config=config) as node:
        sub = node.session.declare_subscriber(f"{args.domain_id}/**", lambda s: meter.on_key(str(s.key_expr)))
        try:
            with RobotWatcher(node, types, grace_s=window) as robots:
                reports = 0
                while True:
                    meter.reset()
                    started = time.monotonic()
                    time.sleep(window)
                    watcher = robots.watcher
                    if watcher is None:
                        break
                    report = graph_report(
                        domain_id=args.domain_id,
                        robots=robots.robots(),
                        nodes=watcher.nodes(),
                        topics=watcher.topics(),
                        services=watcher.services(),
                        rates=meter.rates(time.monotonic() - started),
                        malformed_tokens=watcher.stats.malformed,
                    )
                    print(json.dumps(report) if args.json else render_text(report), file=out, flush=True)
                    reports += 1
                    if not args.watch or (args.count and reports >= args.count):
                        break
        finally:
            sub.undeclare()
    return 0
