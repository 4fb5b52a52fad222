"""``fleetlink spool check DIR`` and ``fleetlink spool acknowledge``: the edge spool, offline.

``check`` reads a spool directory without changing it and prints JSON: segments (file, first and
last seq, records, bytes), records held, records not acknowledged, the ledger's state and every
damage found (file, range, reason, records lost). Exit 0 when nothing awaits an operator, 1 when
damage does, 2 when DIR is not a spool directory.

``acknowledge DIR`` marks the damage findings of a stopped edge's spool acknowledged (the edge no
longer reports ``degraded`` for them); for a running edge, ``acknowledge --admin URL`` asks its
admin API (``POST /spool/damage/acknowledge``, token from ``FLEETLINK_ADMIN_TOKEN`` or
``FLEETLINK_ADMIN_TOKEN_FILE``). See docs/spool.md ("Damage").
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import httpx

from fleetlink.edge.admin.auth import load_token
from fleetlink.edge.errors import SpoolLockedError
from fleetlink.edge.spool.check import acknowledge_offline, check_spool


def register(sub: Any) -> None:
    """Add ``fleetlink spool check`` and ``fleetlink spool acknowledge`` to the subcommands."""
    spool = sub.add_parser("spool", help="inspect the edge spool offline; acknowledge damage")
    spool_sub = spool.add_subparsers(dest="spool_command", metavar="COMMAND")
    spool.set_defaults(handler=lambda _args: _usage(spool))
    check = spool_sub.add_parser(
        "check",
        help="read a spool directory (no change) and print segments, records and damage as JSON",
        description="Exit 0: nothing awaits an operator; 1: damage found; 2: not a spool directory.",
    )
    check.add_argument("dir", type=Path, help="the spool directory (an edge's spool.dir or its durable/)")
    check.set_defaults(handler=check_command)
    ack = spool_sub.add_parser(
        "acknowledge",
        help="acknowledge the spool's damage findings (the edge stops reporting degraded for them)",
    )
    where = ack.add_mutually_exclusive_group(required=True)
    where.add_argument("dir", type=Path, nargs="?", help="the spool directory of a stopped edge")
    where.add_argument(
        "--admin", metavar="URL", help="a running edge's admin API, e.g. http://127.0.0.1:8480"
    )
    ack.set_defaults(handler=acknowledge_command)


def _usage(parser: argparse.ArgumentParser) -> int:
    parser.print_help()
    return 2


def check_command(args: argparse.Namespace) -> int:
    """Print a spool directory's state as JSON; returns 0 when nothing awaits an operator, 1 on damage,
    2 when ``dir`` is not a spool."""
    result = check_spool(args.dir)
    print(json.dumps(result, indent=2, sort_keys=True))
    if "error" in result:
        return 2
    return 0 if result["ok"] else 1


def acknowledge_command(args: argparse.Namespace) -> int:
    """Acknowledge a spool's damage findings, offline or through a running edge's admin API.

    Prints the acknowledged findings as JSON; returns 1 when the admin API or the spool cannot do it.
    """
    if args.admin:
        token = load_token()
        headers = {"Authorization": f"Bearer {token.get_secret_value()}"} if token is not None else {}
        try:
            answer = httpx.post(
                args.admin.rstrip("/") + "/spool/damage/acknowledge", headers=headers, timeout=10.0
            )
        except httpx.HTTPError as exc:
            print(f"fleetlink: error: {args.admin}: {exc}", file=sys.stderr)
            return 1
        if answer.status_code != 200:
            print(
                f"fleetlink: error: {args.admin}: HTTP {answer.status_code}: {answer.text}", file=sys.stderr
            )
            return 1
        done = answer.json().get("acknowledged", [])
    else:
        try:
            done = acknowledge_offline(args.dir, time.time_ns() // 1_000_000)
        except SpoolLockedError as exc:
            print(f"fleetlink: error: {exc}", file=sys.stderr)
            return 1
    print(json.dumps({"acknowledged": done}, indent=2, sort_keys=True))
    return 0
