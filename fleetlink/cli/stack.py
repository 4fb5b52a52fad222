"""``fleetlink stack``: fetch, start, inspect and stop the local Kafka + schema registry."""

from __future__ import annotations

import argparse
import json
import signal
import threading
from pathlib import Path
from typing import Any

from fleetlink.localstack.artifacts import cache_root, fetch_all
from fleetlink.localstack.process import alive
from fleetlink.localstack.registry import registry_url_lines
from fleetlink.localstack.stack import LocalStack, StackInfo, stop_recorded
from fleetlink.schemas.registry_urls import apicurio_native_url

DEFAULT_DIR = Path("var/stack")


def register(sub: Any) -> None:
    """Add ``fleetlink stack`` (``up``, ``down``, ``status``, ``fetch``) to the subcommands."""
    parser: argparse.ArgumentParser = sub.add_parser(
        "stack",
        help="run a local Apache Kafka + Apicurio schema registry (for tests and the demo)",
        description="Run a real single-node Kafka (KRaft) and Apicurio Registry on loopback ports. "
        "Jars come from Maven Central once and are cached (FLEETLINK_CACHE, default ./.cache).",
    )
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)

    up = actions.add_parser("up", help="start Kafka and the registry; print their addresses")
    up.add_argument("--dir", type=Path, default=DEFAULT_DIR, help="state folder (default: %(default)s)")
    up.add_argument("--kafka-port", type=int, default=9092, help="broker port (default: %(default)s)")
    up.add_argument("--registry-port", type=int, default=8081, help="registry port (default: %(default)s)")
    up.add_argument("--foreground", action="store_true", help="stay attached; Ctrl-C stops both services")
    up.set_defaults(handler=_up)

    down = actions.add_parser("down", help="stop a stack started with `stack up`")
    down.add_argument("--dir", type=Path, default=DEFAULT_DIR)
    down.set_defaults(handler=_down)

    status = actions.add_parser("status", help="show whether the stack runs (exit 0) or not (exit 3)")
    status.add_argument("--dir", type=Path, default=DEFAULT_DIR)
    status.add_argument("--json", action="store_true", help="machine-readable output")
    status.set_defaults(handler=_status)

    fetch = actions.add_parser("fetch", help="download the Kafka and Apicurio jars into the cache")
    fetch.set_defaults(handler=_fetch)


def _up(args: argparse.Namespace) -> int:
    existing = StackInfo.load(args.dir)
    if existing and alive(existing.kafka_pid) and alive(existing.registry_pid):
        print(f"already running: Kafka {existing.bootstrap}")
        _print_registry(existing.registry_url)
        return 0
    stack = LocalStack(args.dir, kafka_port=args.kafka_port, registry_port=args.registry_port)
    print("starting Apache Kafka (KRaft) and Apicurio Registry ...", flush=True)
    info = stack.start()
    print(f"Kafka     {info.bootstrap}   (up in {info.kafka_seconds:.1f} s, pid {info.kafka_pid})")
    print(f"Registry  up in {info.registry_seconds:.1f} s, pid {info.registry_pid}")
    _print_registry(info.registry_url)
    if not args.foreground:
        print(f"stop with: fleetlink stack down --dir {args.dir}")
        return 0
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    try:
        print("running; Ctrl-C stops both", flush=True)
        done.wait()
    except KeyboardInterrupt:
        pass
    finally:
        stack.stop()
        print("stopped")
    return 0


def _down(args: argparse.Namespace) -> int:
    print("stopped" if stop_recorded(args.dir) else f"no stack running under {args.dir}")
    return 0


def _status(args: argparse.Namespace) -> int:
    info = StackInfo.load(args.dir)
    running = info is not None and alive(info.kafka_pid) and alive(info.registry_pid)
    if args.json:
        native = {"registry_native_url": apicurio_native_url(info.registry_url)} if info else {}
        print(json.dumps({"running": running, **(info.__dict__ if info else {}), **native}))
    elif info is None:
        print(f"no stack under {args.dir}")
    else:
        state = "running" if running else "not running (stale state)"
        print(f"{state}: Kafka {info.bootstrap}")
        _print_registry(info.registry_url)
    return 0 if running else 3


def _print_registry(url: str) -> None:
    for line in registry_url_lines(url):
        print(f"Registry  {line}")


def _fetch(_args: argparse.Namespace) -> int:
    artifacts = fetch_all()
    print(f"cached in {cache_root()}: Kafka jars and Apicurio ({artifacts.apicurio_jar})")
    return 0
