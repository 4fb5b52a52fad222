"""Fault → light-ring latency of the warehouse demo, over repeated runs.

    .venv/bin/python bench/bench_demo_latency.py [--runs 3] [--window 2s]

Runs the whole demo (`fleetlink demo`: simulated robots → edge → uplink → Kafka → Quix Streams
fault detection → uplink → repeater → robot) ``--runs`` times against one Kafka + registry and
prints, per run and as the median, the time from the fault starting on the robot to the red
light ring at the robot, and from healing to green. The fault-detection window is a lower bound
of the first figure: the app acts only when a whole window of events says "failure".
"""

from __future__ import annotations

import argparse
import io
import os
import statistics
import sys
import tempfile
from contextlib import ExitStack
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fleetlink.common.durations import parse_duration_ms  # noqa: E402
from fleetlink.demo.runner import Demo, DemoOptions  # noqa: E402
from fleetlink.localstack.process import exit_on_sigterm  # noqa: E402
from fleetlink.localstack.stack import LocalStack  # noqa: E402


def main() -> None:
    exit_on_sigterm()  # stopped with SIGTERM: the stack and the processes started here stop too
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--window", default="2s")
    args = ap.parse_args()
    window_s = parse_duration_ms(args.window) / 1000
    with ExitStack() as stack, tempfile.TemporaryDirectory(prefix="fleetlink-demo-bench-") as tmp:
        bootstrap, registry = os.environ.get("KAFKA_BOOTSTRAP"), os.environ.get("SCHEMA_REGISTRY_URL")
        if not (bootstrap and registry):
            local = LocalStack(Path(tmp) / "stack")
            info = local.start()
            stack.callback(local.stop)
            bootstrap, registry = info.bootstrap, info.registry_url
        red: list[float] = []
        green: list[float] = []
        for run in range(args.runs):
            options = DemoOptions(
                workdir=Path(tmp) / f"run{run}",
                bootstrap=bootstrap,
                registry_url=registry,
                window=args.window,
                out=io.StringIO(),
                usual_ports=False,
            )
            summary = Demo(options).run()
            if not summary["loop_closed"]:
                raise SystemExit(f"run {run}: the loop did not close: {summary}")
            red.append(summary["fault_to_red_led_s"])
            green.append(summary["heal_to_green_led_s"])
            print(f"run {run + 1}: fault → red {red[-1]:.2f} s, heal → green {green[-1]:.2f} s", flush=True)
        print(f"\nwindow {window_s:.1f} s; over {args.runs} runs:")
        print(
            f"  fault → red light ring:  p50 {statistics.median(red):.2f} s "
            f"(window {window_s:.1f} s = {window_s / statistics.median(red):.0%} of it)"
        )
        print(f"  heal → green light ring: p50 {statistics.median(green):.2f} s")


if __name__ == "__main__":
    main()
