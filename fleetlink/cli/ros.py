"""``fleetlink ros graph``, ``fleetlink sim`` and ``fleetlink replay``.

Every command opens its zenoh session from Zenoh's usual options (``-e/-l/-m/--zenoh-config``,
``--cfg``) plus ``--domain-id``; with no options it behaves like an rmw_zenoh node (peer,
connecting to a router on ``tcp/127.0.0.1:7447``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
from pathlib import Path
from typing import Any, TextIO

from fleetlink.common.errors import ConfigError
from fleetlink.common.zenoh_options import add_zenoh_arguments, options_from_args

DISTROS = ("humble", "jazzy", "kilted")
MSG_PATH_ENV = "FLEETLINK_MSG_PATH"


def register(sub: Any) -> None:
    ros = sub.add_parser("ros", help="look at the ROS 2 graph on the zenoh network")
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

    sim = sub.add_parser("sim", help="run a simulated TurtleBot 4 fleet (iRobot Create 3 topics)")
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
    _add_types_arguments(sim)
    add_zenoh_arguments(sim)
    sim.set_defaults(handler=sim_command)

    replay = sub.add_parser("replay", help="publish a rosbag2 recording as a robot would")
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
    _add_types_arguments(replay)
    add_zenoh_arguments(replay)
    replay.set_defaults(handler=replay_command)


def _usage(parser: argparse.ArgumentParser) -> int:
    parser.print_help()
    return 2


def _add_types_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--distro",
        choices=DISTROS,
        default="jazzy",
        help="ROS 2 distro whose type hashes to publish (default jazzy)",
    )
    parser.add_argument(
        "--msg-path",
        action="append",
        type=Path,
        default=[],
        metavar="DIR",
        help=f"package folder with msg/*.msg (repeatable; also ${MSG_PATH_ENV})",
    )


def _msg_paths(args: argparse.Namespace) -> list[Path]:
    paths = list(args.msg_path)
    env = os.environ.get(MSG_PATH_ENV, "")
    paths += [Path(p) for p in env.split(os.pathsep) if p]
    for path in paths:
        if not path.is_dir():
            raise ConfigError(f"--msg-path {path}: not a directory")
    return paths


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


# --- sim ------------------------------------------------------------------------------------


def sim_command(args: argparse.Namespace, out: TextIO = sys.stdout, inp: TextIO = sys.stdin) -> int:
    from fleetlink.roswire.session import ros_session_config
    from fleetlink.roswire.sim.fleet import Fleet
    from fleetlink.roswire.sim.messages import IR_VECTOR
    from fleetlink.roswire.sim.model import LedState
    from fleetlink.schemas.typestore import load_typestore

    if args.robots < 0:
        raise ConfigError("--robots must be >= 0")
    # the Create 3 definitions ship with fleetlink; --msg-path adds (or replaces) packages
    ts = load_typestore(args.distro, _msg_paths(args))
    if IR_VECTOR not in ts.fielddefs:
        raise ConfigError(
            "the simulator needs the irobot_create_msgs definitions: pass "
            f"--msg-path DIR/irobot_create_msgs (or set ${MSG_PATH_ENV})"
        )
    lock = threading.Lock()

    def say(text: str) -> None:
        with lock:
            print(text, file=out, flush=True)

    def on_led(robot: str, state: LedState) -> None:
        say(f"{robot} light ring: {state.name}")

    config = ros_session_config(options_from_args(args))
    with Fleet(
        config,
        ts,
        robots=args.robots,
        prefix=args.prefix,
        rate=args.rate,
        domain_id=args.domain_id,
        distro=args.distro,
        on_led=on_led,
    ) as fleet:
        for robot in args.fault:
            fleet.inject_fault(robot)
        say(
            f"simulating {', '.join(fleet.names()) or 'no robots'} at {args.rate:g} Hz "
            f"on domain {args.domain_id}"
        )
        if args.stdin:
            _command_loop(fleet, inp, say, args.duration)
        elif args.duration:
            time.sleep(args.duration)
        else:
            while True:
                time.sleep(3600)
    return 0


def _command_loop(fleet: Any, inp: TextIO, say: Any, duration: float | None) -> None:
    from fleetlink.roswire.errors import RoswireError

    deadline = None if duration is None else time.monotonic() + duration
    console = _FleetConsole(fleet)
    for line in inp:
        words = line.split()
        if not words:
            continue
        if words[0] == "quit":
            return
        try:
            say(console.run(words))
        except RoswireError as exc:
            say(f"error: {exc}")
        if deadline is not None and time.monotonic() >= deadline:
            return
    if deadline is not None:  # stdin closed early: keep running for the rest of the duration
        time.sleep(max(0.0, deadline - time.monotonic()))


class _FleetConsole:
    """The stdin commands of ``fleetlink sim --stdin``; each returns the line to print."""

    usage = "fault R, heal R, add [R], remove R, led R, list, quit"

    def __init__(self, fleet: Any) -> None:
        self.fleet = fleet

    def run(self, words: list[str]) -> str:
        action = getattr(self, f"do_{words[0]}", None)
        needs_name = words[0] in ("fault", "heal", "remove", "led")
        if action is None or (needs_name and len(words) < 2):
            return f"unknown command {' '.join(words)!r} ({self.usage})"
        result: str = action(words[1] if len(words) > 1 else None)
        return result

    def do_fault(self, name: str) -> str:
        self.fleet.inject_fault(name)
        return f"{name} picked up"

    def do_heal(self, name: str) -> str:
        self.fleet.heal(name)
        return f"{name} back on the floor"

    def do_add(self, name: str | None) -> str:
        return f"{self.fleet.add_robot(name)} added"

    def do_remove(self, name: str) -> str:
        self.fleet.remove_robot(name)
        return f"{name} removed"

    def do_led(self, name: str) -> str:
        return f"{name} light ring: {self.fleet.led(name).name}"

    def do_list(self, _name: str | None) -> str:
        return " ".join(self.fleet.names())


# --- replay ---------------------------------------------------------------------------------


def replay_command(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    from fleetlink.roswire.replay import BagReplayer
    from fleetlink.roswire.session import ros_session_config

    rate = 0.0 if args.fast else args.rate
    if rate < 0:
        raise ConfigError("--rate must be >= 0 (0 = as fast as possible)")
    config = ros_session_config(options_from_args(args))
    with BagReplayer(
        args.bag,
        args.robot,
        config=config,
        domain_id=args.domain_id,
        distro=args.distro,
        msg_paths=_msg_paths(args),
        rate=rate,
        loop=args.loop,
        topics=args.topic,
    ) as replayer:
        topics = ", ".join(p.topic for p in replayer.publishers.values())
        print(f"replaying {args.bag} as /{args.robot}: {topics}", file=out, flush=True)
        if args.wait_subscribers > 0 and not replayer.wait_for_subscribers(args.wait_subscribers):
            print("not every topic has a subscriber; replaying anyway", file=out, flush=True)
        try:
            stats = replayer.run()
        except KeyboardInterrupt:
            replayer.request_stop()
            stats = replayer.stats
    print(
        f"published {stats.total} messages on {len(stats.published)} topics in {stats.elapsed_s:.2f} s"
        f" ({stats.loops} pass{'es' if stats.loops != 1 else ''})",
        file=out,
        flush=True,
    )
    return 0
