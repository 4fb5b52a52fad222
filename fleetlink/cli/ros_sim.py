"""``fleetlink ros sim`` and ``fleetlink ros replay``: robots that are not there, on the wire.

``sim`` runs a simulated TurtleBot 4 fleet (iRobot Create 3 topics) in this process; ``replay``
publishes a rosbag2 recording as one robot would. Both speak rmw_zenoh like real robots.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from typing import Any, TextIO

from fleetlink.cli.ros_common import MSG_PATH_ENV, msg_paths
from fleetlink.common.errors import ConfigError
from fleetlink.common.zenoh_options import options_from_args

# --- sim ------------------------------------------------------------------------------------


def sim_command(args: argparse.Namespace, out: TextIO = sys.stdout, inp: TextIO = sys.stdin) -> int:
    """Simulate a TurtleBot 4 fleet, printing light-ring changes, for ``--duration`` or until stopped.

    With ``--stdin`` it takes commands (fault, heal, add, remove, led, list, quit) line by line.
    """
    from fleetlink.roswire.session import ros_session_config
    from fleetlink.roswire.sim.fleet import Fleet
    from fleetlink.roswire.sim.messages import IR_VECTOR
    from fleetlink.roswire.sim.model import LedState
    from fleetlink.schemas.typestore import load_typestore

    if args.robots < 0:
        raise ConfigError("--robots must be >= 0")
    # the Create 3 definitions ship with fleetlink; --msg-path adds (or replaces) packages
    ts = load_typestore(args.distro, msg_paths(args))
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
    """The stdin commands of ``fleetlink ros sim --stdin``; each returns the line to print."""

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
    """Publish a rosbag2 recording under ``/<--robot>`` at its recorded pace (or faster); print totals."""
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
        msg_paths=msg_paths(args),
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
