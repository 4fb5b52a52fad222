"""Memory soak: a full spool under a steady 5,000 msg/s with the WAN cut, for minutes.

    .venv/bin/python bench/bench_soak.py [--seconds 300] [--policy block ...] [--robots 10] [--hz 500]

The suite's soak (tests/fault/test_memory_soak.py) holds 20 s; this holds as long as asked. Ten
robots (each its own Zenoh session) publish Imu messages into an edge agent (a process) whose
4 MiB spool fills within seconds and whose WAN link is cut: every message must be accounted for
(lost in transit, dropped at the intake, held, evicted or refused by the spool, each counted
once) and the edge's resident memory must stop growing once the spool is full. Prints, per
policy, where the messages went, the edge's RSS every tenth of the run and its growth after the
warm-up, against the configured memory bound (``EdgeConfig.memory_bound``).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.fault.soak import run_soak  # noqa: E402

POLICIES = ("block", "drop_oldest", "drop_newest")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=300.0, help="how long the robots publish")
    ap.add_argument("--policy", action="append", choices=POLICIES, help="full policies (default: all)")
    ap.add_argument("--robots", type=int, default=10)
    ap.add_argument("--hz", type=float, default=500.0, help="messages per second of each robot")
    args = ap.parse_args()
    failed = False
    for policy in args.policy or POLICIES:
        with tempfile.TemporaryDirectory(prefix="fleetlink-soak-") as tmp:
            began = time.monotonic()
            soak = run_soak(Path(tmp), policy, robots=args.robots, hz=args.hz, seconds=args.seconds)
            took = time.monotonic() - began
        accounted = soak.accounted()
        balanced = sum(accounted.values()) == soak.published + soak.registrations
        step = max(1, len(soak.rss_mb) // 10)
        timeline = " ".join(f"{mb:.0f}" for mb in soak.rss_mb[::step])
        bound = soak.stats.get("memory", {}).get("bound_bytes", 0) / (1 << 20)
        print(f"{soak.summary()}  [{took:.0f} s]", flush=True)
        print(f"   edge RSS every {args.seconds / 10:.0f} s (MB): {timeline}; memory bound {bound:.0f} MB")
        print(f"   every message accounted for: {'yes' if balanced else 'NO'}; growth x{soak.growth():.3f}")
        failed |= not balanced or soak.growth() > 1.10
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
