"""A Zenoh router as its own process, for the benchmarks: ``fleet_router.py PORT [CONNECT ...]``.

Prints ``ready`` once it listens on tcp/127.0.0.1:PORT (and connects to the given endpoints), then
runs until its stdin closes.
"""

from __future__ import annotations

import sys

from fleetlink.localstack.zenoh_router import ZenohRouter


def main() -> int:
    port, *connect = sys.argv[1:]
    # a site of 1,000 robots is over 1,000 sessions (zenoh's default refuses the 1,001st), and with
    # shared memory on, a router has counters for some 350 same-host sessions only
    extra = {"transport/unicast/max_sessions": 20000, "transport/shared_memory/enabled": False}
    with ZenohRouter(int(port), connect=tuple(connect), extra=extra):
        print("ready", flush=True)
        sys.stdin.read()
    return 0


if __name__ == "__main__":
    sys.exit(main())
