"""``fleetlink ros echo`` and ``fleetlink ros pub``: a topic from the command line, as
``ros2 topic echo`` and ``ros2 topic pub`` do it.

``echo TOPIC [TYPE]`` prints each message as YAML followed by ``---`` (``--json``: one JSON line
each); without a type it waits for a publisher and takes its type, and without ``--qos`` it
adapts to the publishers' QoS (best effort if any is, transient local if all are).
``pub TOPIC TYPE 'YAML'`` publishes the message at ``--rate`` (default 1 Hz) until interrupted,
``--once`` or ``--times N``; fields not given keep their defaults. The types are the distro's,
the bundled packages' and those of ``--msg-path``.
"""

from __future__ import annotations

import argparse
import json
import queue
import sys
import time
from typing import TYPE_CHECKING, Any, TextIO

import yaml

from fleetlink.cli.ros_common import add_types_arguments, typestore
from fleetlink.common.errors import ConfigError
from fleetlink.common.zenoh_options import add_zenoh_arguments, options_from_args

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

    from fleetlink.roswire.discovery import GraphWatcher
    from fleetlink.roswire.qos import QoS

TRUNCATE = 128
"""Items of an array printed by default, as ``ros2 topic echo``."""

QOS_HELP = (
    "a profile (default, sensor_data, transient_local, services) or settings such as "
    "'best_effort, transient_local, keep_last 5'"
)


def register_echo(sub: Any) -> None:
    """Add ``fleetlink ros echo`` to the ``ros`` subcommands."""
    echo = sub.add_parser("echo", help="print the messages of a topic (like ros2 topic echo)")
    echo.add_argument("topic", help="e.g. /tb4_01/kidnap_status")
    echo.add_argument("type", nargs="?", help="message type (default: the publishers')")
    echo.add_argument("--once", action="store_true", help="print one message, then exit")
    echo.add_argument("--count", type=int, metavar="N", help="print N messages, then exit")
    echo.add_argument("--timeout", type=float, metavar="S", help="exit 1 if no message came within S seconds")
    echo.add_argument("--qos", metavar="PROFILE", help=QOS_HELP + " (default: adapt to the publishers)")
    echo.add_argument("--json", action="store_true", help="one JSON object per line instead of YAML")
    echo.add_argument(
        "--full-length", action="store_true", help=f"print whole arrays (default: the first {TRUNCATE} items)"
    )
    add_types_arguments(echo)
    add_zenoh_arguments(echo)
    echo.set_defaults(handler=echo_command)


def register_pub(sub: Any) -> None:
    """Add ``fleetlink ros pub`` to the ``ros`` subcommands."""
    pub = sub.add_parser("pub", help="publish a message on a topic (like ros2 topic pub)")
    pub.add_argument("topic", help="e.g. /tb4_01/cmd_lightring")
    pub.add_argument("type", help="message type, e.g. std_msgs/msg/String")
    pub.add_argument("values", nargs="?", default="{}", help="the message as YAML, e.g. '{data: hello}'")
    pub.add_argument("-1", "--once", action="store_true", help="publish one message, then exit")
    pub.add_argument("-t", "--times", type=int, metavar="N", help="publish N messages, then exit")
    pub.add_argument(
        "-r", "--rate", type=float, default=1.0, metavar="HZ", help="messages per second (default 1)"
    )
    pub.add_argument("--qos", metavar="PROFILE", help=QOS_HELP + " (default: default)")
    pub.add_argument(
        "-w",
        "--wait-matching-subscriptions",
        type=int,
        metavar="N",
        help="wait for N subscriptions first (default 1 with --once or --times, else 0)",
    )
    pub.add_argument(
        "--timeout",
        type=float,
        metavar="S",
        help="with -w: exit 1 if the subscriptions are not there within S seconds",
    )
    pub.add_argument(
        "--keep-alive",
        type=float,
        default=0.5,
        metavar="S",
        help="stay this long after the last message (default 0.5 s)",
    )
    add_types_arguments(pub)
    add_zenoh_arguments(pub)
    pub.set_defaults(handler=pub_command)


# --- pure helpers -------------------------------------------------------------------------


def truncated(data: Any, limit: int) -> Any:
    """Arrays cut to ``limit`` items, the rest shown as one ``'...'`` (as ros2 prints them)."""
    if isinstance(data, dict):
        return {k: truncated(v, limit) for k, v in data.items()}
    if isinstance(data, list):
        items = [truncated(v, limit) for v in data[:limit]]
        return [*items, "..."] if len(data) > limit else items
    return data


def render_message(data: Any, *, as_json: bool) -> str:
    """A message's data as one JSON line, or as a YAML document ending in ``---``."""
    if as_json:
        return json.dumps(data, separators=(",", ":"), ensure_ascii=False)
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=False, allow_unicode=True) + "---"


def parse_values(text: str) -> Any:
    """The message values given as YAML text (empty text as ``{}``); ``ConfigError`` when not YAML."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"the message is not valid YAML: {exc}") from None
    return {} if data is None else data


def known_type(ts: Typestore, name: str) -> str:
    """``name`` as a normalized type name of ``ts``; ``ConfigError`` when the type is unknown."""
    from fleetlink.schemas.typestore import normalize_typename

    typename = normalize_typename(name)
    if typename not in ts.fielddefs:
        raise ConfigError(
            f"unknown message type {typename!r}: not a type of the distro or of the packages "
            "fleetlink ships; add its package with --msg-path DIR"
        )
    return typename


def qos_option(text: str | None) -> QoS | None:
    """The QoS profile given with ``--qos`` (None when not given); ``ConfigError`` when it does not parse."""
    from fleetlink.roswire.errors import QosParseError
    from fleetlink.roswire.qos import parse_profile

    if text is None:
        return None
    try:
        return parse_profile(text)
    except QosParseError as exc:
        raise ConfigError(f"--qos: {exc}") from None


# --- echo ---------------------------------------------------------------------------------


def echo_command(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    """Print a topic's messages, subscribing with the publishers' type and QoS unless given.

    Returns 1 when no publisher or message came within ``--timeout``, else 0.
    """
    from fleetlink.roswire.discovery import GraphWatcher
    from fleetlink.roswire.node import RosNode
    from fleetlink.roswire.session import ros_session_config

    limit = 1 if args.once else args.count
    if limit is not None and limit < 1:
        raise ConfigError("--count must be at least 1")
    ts = typestore(args)
    asked_type = None if args.type is None else known_type(ts, args.type)
    asked_qos = qos_option(args.qos)
    deadline = None if args.timeout is None else time.monotonic() + args.timeout
    config = ros_session_config(options_from_args(args))
    with (
        RosNode(
            "fleetlink_echo", domain_id=args.domain_id, config=config, typestore=ts, distro=args.distro
        ) as node,
        GraphWatcher(node.session, args.domain_id) as graph,
    ):
        topic = node.resolve(args.topic)
        typename, qos = _echo_settings(graph, topic, asked_type, asked_qos, deadline)
        if typename is None:
            print(f"no publisher of {topic} within {args.timeout:g} s", file=sys.stderr)
            return 1
        typename = known_type(ts, typename)
        samples: queue.Queue[Any] = queue.Queue()
        node.create_subscriber(topic, typename, samples.put, qos, decode=True)
        return _print_samples(samples, out, limit=limit, deadline=deadline, args=args, topic=topic)


def _echo_settings(
    graph: GraphWatcher, topic: str, typename: str | None, qos: QoS | None, deadline: float | None
) -> tuple[str | None, QoS]:
    """The type and QoS to subscribe with: as asked, else the publishers' (waited for when the
    type is unknown; a moment when only the QoS is)."""
    from fleetlink.roswire.qos import DEFAULT, adapted

    if typename is not None and qos is not None:
        return typename, qos
    settle = time.monotonic() + 1.0  # tokens of publishers that are already there arrive at once
    while True:
        info = graph.topics().get(topic)
        if info is not None and info.publishers:
            qos = qos or adapted([p.qos for p in info.publishers])
            return typename or info.types[0], qos
        now = time.monotonic()
        if typename is not None and now >= settle:
            return typename, qos or DEFAULT
        if deadline is not None and now >= deadline:
            return None, DEFAULT
        time.sleep(0.05)  # ok-sleep: polling the graph for a publisher


def _print_samples(
    samples: queue.Queue[Any],
    out: TextIO,
    *,
    limit: int | None,
    deadline: float | None,
    args: argparse.Namespace,
    topic: str,
) -> int:
    from fleetlink.schemas.messages import to_data

    printed = 0
    while limit is None or printed < limit:
        wait = None if deadline is None or printed else max(0.0, deadline - time.monotonic())
        try:
            sample = samples.get(timeout=wait)
        except queue.Empty:
            print(f"no message on {topic} within {args.timeout:g} s", file=sys.stderr)
            return 1
        data = to_data(sample.message)
        if not args.full_length:
            data = truncated(data, TRUNCATE)
        print(render_message(data, as_json=args.json), file=out, flush=True)
        printed += 1
    return 0


# --- pub ----------------------------------------------------------------------------------


def pub_command(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    """Publish a message on a topic at ``--rate``, once, N times or until stopped.

    Returns 1 when the subscriptions waited for did not appear within ``--timeout``, else 0.
    """
    from fleetlink.roswire.discovery import GraphWatcher
    from fleetlink.roswire.node import RosNode
    from fleetlink.roswire.qos import DEFAULT
    from fleetlink.roswire.session import ros_session_config
    from fleetlink.schemas.messages import from_data

    if args.rate <= 0:
        raise ConfigError("--rate must be above 0")
    times = 1 if args.once else args.times
    if times is not None and times < 1:
        raise ConfigError("--times must be at least 1")
    wait_for = args.wait_matching_subscriptions
    if wait_for is None:
        wait_for = 1 if times is not None else 0
    ts = typestore(args)
    typename = known_type(ts, args.type)
    message = from_data(ts, typename, parse_values(args.values))
    qos = qos_option(args.qos) or DEFAULT
    config = ros_session_config(options_from_args(args))
    with RosNode(
        "fleetlink_pub", domain_id=args.domain_id, config=config, typestore=ts, distro=args.distro
    ) as node:
        publisher = node.create_publisher(args.topic, typename, qos)
        if wait_for > 0:
            with GraphWatcher(node.session, args.domain_id) as graph:
                if not _wait_for_subscriptions(graph, publisher.topic, wait_for, args.timeout):
                    print(
                        f"fewer than {wait_for} subscription(s) on {publisher.topic} within "
                        f"{args.timeout:g} s",
                        file=sys.stderr,
                    )
                    return 1
        shown = json.dumps(_shown(message), separators=(", ", ": "), ensure_ascii=False)
        sent = 0
        period = 1.0 / args.rate
        next_at = time.monotonic()
        while times is None or sent < times:
            publisher.publish(message)
            sent += 1
            print(f"publishing #{sent} on {publisher.topic}: {shown}", file=out, flush=True)
            if times is not None and sent >= times:
                break
            next_at += period
            time.sleep(max(0.0, next_at - time.monotonic()))  # ok-sleep: the publishing rate
        time.sleep(max(0.0, args.keep_alive))  # ok-sleep: let the last message reach slow subscribers
    return 0


def _shown(message: Any) -> Any:
    from fleetlink.schemas.messages import to_data

    return to_data(message)


def _wait_for_subscriptions(graph: GraphWatcher, topic: str, count: int, timeout: float | None) -> bool:
    deadline = None if timeout is None else time.monotonic() + timeout
    while True:
        info = graph.topics().get(topic)
        if info is not None and len(info.subscribers) >= count:
            return True
        if deadline is not None and time.monotonic() >= deadline:
            return False
        time.sleep(0.05)  # ok-sleep: polling the graph for subscriptions
