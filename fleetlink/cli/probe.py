"""``fleetlink probe URL``: exit 0 when an HTTP endpoint answers 2xx (container healthchecks).

The image has no curl or wget; ``/health`` of the edge (admin port) and the uplink (metrics port)
is probed with this. Exit 1 with the reason otherwise.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any


def register(sub: Any) -> None:
    """Add ``fleetlink probe URL`` (exit 0 on a 2xx answer) to the subcommands."""
    parser: argparse.ArgumentParser = sub.add_parser(
        "probe",
        help="exit 0 if an HTTP URL answers 2xx (for healthchecks: /health)",
        description="GET a URL; exit 0 on a 2xx answer, 1 otherwise (the reason on stderr).",
    )
    parser.add_argument("url", help="e.g. http://127.0.0.1:8480/health")
    parser.add_argument("--timeout", type=float, default=3.0, metavar="S", help="per request (default 3 s)")
    parser.add_argument(
        "--wait",
        type=float,
        default=0.0,
        metavar="S",
        help="ask again until it answers, for up to S seconds (for scripts starting a service)",
    )
    parser.set_defaults(handler=_probe)


def _probe(args: argparse.Namespace) -> int:
    deadline = time.monotonic() + max(0.0, args.wait)
    while True:
        problem = _ask(args.url, args.timeout)
        if problem is None:
            return 0
        if time.monotonic() >= deadline:
            print(f"{args.url}: {problem}", file=sys.stderr)
            return 1
        time.sleep(0.5)  # ok-sleep: --wait polls a starting service


def _ask(url: str, timeout: float) -> str | None:
    """None when ``url`` answers 2xx, else why not."""
    import httpx

    try:
        response = httpx.get(url, timeout=timeout)
    except httpx.HTTPError as exc:
        return str(exc) or type(exc).__name__
    return None if response.is_success else f"HTTP {response.status_code}"
