"""Robots for the fleet benchmark: each robot its own Zenoh session (as an rmw_zenoh process),
publishing real recorded messages on five topics at a steady rate.

Run by bench/bench_fleet.py: ``fleet_publisher.py --connect EP --first N --robots K --hz F``.
Declares the robots (node, publishers), prints ``ready``, waits for a line on stdin, publishes
every topic of every robot at ``--hz`` for ``--seconds`` (the publications evenly spread over
each period, robot after robot; with ``--tick`` those due within a tick leave together, a
wake-up a tick instead of one a publication), the first and the last sample of each topic
waiting for room instead of being dropped (a sample lost on the way between them is a gap in
the sequence numbers at the edge; one lost before a publisher's first sample the edge receives
would be counted nowhere), prints ``done <published> <seconds> <behind>`` (``behind``:
publications that left more than one period late), then waits for a line before closing the
sessions.
"""

from __future__ import annotations

import argparse
import gc
import sys
import time

from rosbags.rosbag2 import Reader

from fleetlink.common.zenoh_options import ZenohOptions
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.publisher import RosPublisher
from fleetlink.roswire.session import ros_session_config
from fleetlink.schemas.typestore import load_typestore
from tests.paths import HUSKY, TURTLEBOT3

TOPICS: tuple[tuple[str, str, str, object], ...] = (
    # (robot topic, ROS type, bag topic, bag)
    ("imu", "sensor_msgs/msg/Imu", "/imu/data", HUSKY),
    ("odom", "nav_msgs/msg/Odometry", "/husky_velocity_controller/odom", HUSKY),
    ("fix", "sensor_msgs/msg/NavSatFix", "/fix", HUSKY),
    ("scan", "sensor_msgs/msg/LaserScan", "/scan", TURTLEBOT3),
    ("joint_states", "sensor_msgs/msg/JointState", "/joint_states", TURTLEBOT3),
)


def recorded(limit: int = 200) -> dict[str, list[bytes]]:
    """Up to ``limit`` real messages of each topic, from the recorded bags."""
    out: dict[str, list[bytes]] = {}
    for name, _type, bag_topic, bag in TOPICS:
        with Reader(bag) as reader:  # type: ignore[arg-type]
            conns = [c for c in reader.connections if c.topic == bag_topic]
            msgs = out.setdefault(name, [])
            for _c, _t, raw in reader.messages(connections=conns):
                msgs.append(bytes(raw))
                if len(msgs) >= limit:
                    break
    return out


def subscribed(publishers: list[RosPublisher], timeout_s: float) -> bool:
    """Whether a subscriber matches every publisher within ``timeout_s`` (samples published before
    the router knows the subscriber would be lost on the way)."""
    deadline = time.monotonic() + timeout_s
    waiting = list(publishers)
    while waiting:
        waiting = [pub for pub in waiting if not pub.has_subscribers()]
        if waiting and time.monotonic() > deadline:
            return False
        if waiting:
            time.sleep(0.01)
    return True


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--connect", required=True)
    parser.add_argument("--first", type=int, default=0, help="number of the first robot")
    parser.add_argument("--robots", type=int, required=True)
    parser.add_argument("--topics", type=int, default=len(TOPICS))
    parser.add_argument("--hz", type=float, required=True, help="messages/s per topic")
    parser.add_argument("--seconds", type=float, required=True)
    parser.add_argument(
        "--block", action="store_true", help="reliable and blocking publishers: nothing dropped on the way"
    )
    parser.add_argument(
        "--tick",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="wake at most once per tick (at most half the period) and publish what is due then"
        " (0: a wake-up per publication)",
    )
    parser.add_argument(
        "--wait-subscribed",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="after 'go', wait up to this long until a subscriber matches every publisher (exit 3 if not)",
    )
    args = parser.parse_args()

    ts = load_typestore("jazzy")
    payloads = recorded()
    config = ros_session_config(ZenohOptions(mode="client", connect=(args.connect,)))
    topics = TOPICS[: args.topics]
    nodes: list[RosNode] = []
    pubs: list[tuple[RosPublisher, list[bytes]]] = []
    for i in range(args.first, args.first + args.robots):
        node = RosNode("driver", f"/r{i:04d}", config=config, typestore=ts).start()
        nodes.append(node)
        for name, typename, _bag_topic, _bag in topics:
            congestion = "block" if args.block else None
            pubs.append(
                (node.create_publisher(f"/r{i:04d}/{name}", typename, congestion=congestion), payloads[name])
            )
    # robot by robot within a topic: publications that leave in one tick come from different
    # robots (different sessions), as independent robots' would, not one robot's topics together
    pubs = [pubs[r * len(topics) + t] for t in range(len(topics)) for r in range(args.robots)]
    gc.freeze()
    print("ready", flush=True)
    sys.stdin.readline()
    if args.wait_subscribed > 0 and not subscribed([pub for pub, _msgs in pubs], args.wait_subscribed):
        unmatched = sum(not pub.has_subscribers() for pub, _msgs in pubs)
        print(f"unmatched {unmatched} publisher(s) after {args.wait_subscribed} s", flush=True)
        return 3
    published = behind = 0
    if args.hz > 0:
        interval = 1.0 / (args.hz * len(pubs))  # every publisher once per period, evenly spread
        period = 1.0 / args.hz
        tick = min(args.tick, period / 2)  # a publisher never leaves twice in one tick
        total = int(args.seconds * args.hz) * len(pubs)
        began = time.perf_counter()
        for n in range(total):
            due = began + n * interval
            delay = due - time.perf_counter()
            if delay > 0:
                time.sleep(max(delay, tick))
            elif -delay > period:
                behind += 1
            pub, msgs = pubs[n % len(pubs)]
            pub.publish_cdr(msgs[(n // len(pubs)) % len(msgs)], block=n < len(pubs))
            published += 1
        for pub, msgs in pubs:  # a last sample each that is never dropped: any loss before it is a gap
            pub.publish_cdr(msgs[0], block=True)
            published += 1
        elapsed = time.perf_counter() - began
    else:
        time.sleep(args.seconds)
        elapsed = args.seconds
    print(f"done {published} {elapsed:.3f} {behind}", flush=True)
    sys.stdin.readline()
    for node in nodes:
        node.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
