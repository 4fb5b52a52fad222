"""Robots for the end-to-end benchmark: K rmw_zenoh publishers of real Husky IMU messages.

Run by bench/bench_e2e.py as its own process. Declares one node and one ``/<robot>/imu``
publisher per robot, prints ``ready``, waits for a line on stdin, publishes ``--count``
messages per robot (round-robin over the robots, at ``--rate`` messages/s in total, 0 = as fast
as possible), then prints ``done <messages> <seconds>``.
"""

from __future__ import annotations

import argparse
import gc
import sys
import time

from rosbags.rosbag2 import Reader

from fleetlink.common.zenoh_options import ZenohOptions
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.qos import History, QoS
from fleetlink.roswire.session import ros_session_config
from fleetlink.schemas.typestore import load_typestore
from tests.paths import HUSKY

IMU = "sensor_msgs/msg/Imu"


def imu_payloads(limit: int) -> list[bytes]:
    out: list[bytes] = []
    with Reader(HUSKY) as reader:
        conns = [c for c in reader.connections if c.topic == "/imu/data"]
        for _c, _t, raw in reader.messages(connections=conns):
            out.append(bytes(raw))
            if len(out) >= limit:
                break
    return out


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--connect", required=True)
    parser.add_argument("--robots", type=int, default=4)
    parser.add_argument("--count", type=int, default=10_000, help="messages per robot")
    parser.add_argument("--rate", type=float, default=0.0, help="total messages/s (0 = max)")
    parser.add_argument("--prefix", default="r")
    args = parser.parse_args()

    ts = load_typestore("jazzy")
    payloads = imu_payloads(2000)
    config = ros_session_config(ZenohOptions(mode="client", connect=(args.connect,)))
    nodes = [
        RosNode("imu_driver", f"/{args.prefix}{i:02d}", config=config, typestore=ts).start()
        for i in range(args.robots)
    ]
    qos = QoS(history=History.KEEP_ALL, depth=1000)  # reliable and blocking: no sample dropped
    pubs = [n.create_publisher(f"/{args.prefix}{i:02d}/imu", IMU, qos) for i, n in enumerate(nodes)]
    gc.freeze()  # nothing made so far is garbage: keep full collections short while publishing
    print("ready", flush=True)
    sys.stdin.readline()
    total = args.count * args.robots
    interval = 1.0 / args.rate if args.rate > 0 else 0.0
    began = time.perf_counter()
    for i in range(total):
        if interval:
            target = began + i * interval
            delay = target - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        pubs[i % len(pubs)].publish_cdr(payloads[i % len(payloads)])
    elapsed = time.perf_counter() - began
    print(f"done {total} {elapsed:.3f}", flush=True)
    sys.stdin.readline()  # stay alive (tokens declared) until told to go
    for node in nodes:
        node.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
