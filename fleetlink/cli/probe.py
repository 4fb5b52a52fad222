"""``fleetlink probe URL``: exit 0 when an HTTP endpoint answers 2xx (container healthchecks).

The image has no curl or wget; ``/health`` of the edge (admin port) and the uplink (metrics port)
is probed with this. Exit 1 with the reason otherwise.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any


def register(sub: Any) -> None:
    parser: argparse.ArgumentParser = sub.add_parser(
        "probe",
        help="exit 0 if an HTTP URL answers 2xx (for healthchecks: /health)",
        description="GET a URL; exit 0 on a 2xx answer, 1 otherwise (the reason on stderr).",
    )
    parser.add_argument("url", help="e.g. http://127.0.0.1:8480/health")
    parser.add_argument("--timeout", type=float, default=3.0, metavar="S", help="default 3 s")
    parser.set_defaults(handler=_probe)


def _probe(args: argparse.Namespace) -> int:
    import httpx

    try:
        response = httpx.get(args.url, timeout=args.timeout)
    except httpx.HTTPError as exc:
        print(f"{args.url}: {exc}", file=sys.stderr)
        return 1
    if not response.is_success:
        print(f"{args.url}: HTTP {response.status_code}", file=sys.stderr)
        return 1
    return 0
