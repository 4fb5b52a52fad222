"""The floor of the fleet benchmark's receive path: a bare Zenoh client of the site router.

Run by bench/bench_fleet.py (``--bare``): ``bare_receiver.py --connect EP --topic NAME ...``.
Opens a client session with the runtime the edge's data plane uses (every Zenoh task on one
thread, ``DATAPLANE_RUNTIME``), subscribes to every robot's samples of each topic (one wildcard a
topic) into a ring of one that nobody reads, prints ``ready`` and waits for a line on stdin. Its
CPU is what receiving the fleet's samples through Zenoh costs on this machine before any work is
done with them: the part of the edge's cost that no code of the edge can remove.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fleetlink.edge.runtime.dataplane import DATAPLANE_RUNTIME  # noqa: E402

os.environ["ZENOH_RUNTIME"] = DATAPLANE_RUNTIME
import zenoh  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--connect", required=True, help="the site router's endpoint")
    ap.add_argument("--topic", action="append", default=[], help="a robot topic's name (repeat)")
    args = ap.parse_args()
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", f'["{args.connect}"]')
    config.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(config) as session:
        subscribers = [
            session.declare_subscriber(f"*/*/{name}/**", zenoh.handlers.RingChannel(1)) for name in args.topic
        ]
        print("ready", flush=True)
        sys.stdin.readline()
        for subscriber in subscribers:
            subscriber.undeclare()


if __name__ == "__main__":
    main()
