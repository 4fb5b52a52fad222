"""``fleetlink edge run -c edge.yaml [zenoh options]``: run the edge agent until SIGTERM/SIGINT.

The config is validated before anything is opened (errors name the YAML path, exit 1). On
SIGTERM or SIGINT the agent stops cleanly within ``--stop-timeout`` (what is in flight gets its
acknowledgement, the spool is flushed and closed) and the command exits 0.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import threading
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any

from fleetlink.cli.configs import add_set_argument, load_service
from fleetlink.cli.logs import SERVICE_VERBOSITY
from fleetlink.common.extras import MissingExtraError
from fleetlink.common.zenoh_options import add_zenoh_arguments, options_from_args

if TYPE_CHECKING:
    from pydantic import SecretStr

    from fleetlink.edge.admin.server import ExtensionFactory

log = logging.getLogger(__name__)


def register(sub: Any) -> None:
    """Add ``fleetlink edge run`` and its options to the subcommands."""
    edge = sub.add_parser("edge", help="the edge agent (one per robot network)")
    edge_sub = edge.add_subparsers(dest="edge_command", metavar="COMMAND")
    edge.set_defaults(handler=lambda _args: _usage(edge))
    run = edge_sub.add_parser("run", help="run the edge agent")
    run.add_argument("-c", "--config", type=Path, required=True, metavar="FILE", help="edge YAML config")
    add_set_argument(run)
    run.add_argument(
        "--stop-timeout",
        type=float,
        default=5.0,
        metavar="S",
        help="on SIGTERM, how long unacknowledged batches may still be sent (default 5 s)",
    )
    run.add_argument(
        "--stats-file",
        type=Path,
        metavar="FILE",
        help="write the agent's counters as JSON to FILE every --stats-interval seconds",
    )
    run.add_argument(
        "--stats-interval",
        type=float,
        default=1.0,
        metavar="S",
        help="how often to write --stats-file (default 1 s)",
    )
    add_zenoh_arguments(run, ros=False)
    run.set_defaults(handler=run_command, log_verbosity=SERVICE_VERBOSITY)


def _usage(parser: argparse.ArgumentParser) -> int:
    parser.print_help()
    return 2


def write_stats(path: Path, snapshot: dict[str, Any]) -> None:
    """Replace ``path`` atomically with the snapshot as JSON."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(snapshot, default=str, sort_keys=True), encoding="utf-8")
    os.replace(tmp, path)


def console_extensions(token: SecretStr | None, edge_id: str) -> list[ExtensionFactory]:
    """The web console beside the admin API, when its extra is installed (else the API alone)."""
    try:
        from fleetlink.console.edge import console_extension
    except MissingExtraError as exc:
        log.info("%s; the admin API runs without it", exc)
        return []
    return [console_extension(token, edge_id)]


ZENOH_RUNTIME = "(rx: (worker_threads: 1))"
"""The edge's default Zenoh runtime (``ZENOH_RUNTIME`` wins): one receive worker. At 10,000 samples/s
from a thousand publishers, two workers handing each sample's wake-up between them cost the
edge's data plane some 4 µs a sample more (bench/bench_fleet.py). Handing every runtime over to
one thread saved as much again in a client-mode edge, but a router-mode edge (the robots'
router in the edge's process) then dropped most of a burst: not done."""


def run_command(args: argparse.Namespace) -> int:
    """Run the edge agent and its admin API until SIGTERM or SIGINT; returns the exit code.

    Writes the agent's counters to ``--stats-file`` every ``--stats-interval`` seconds and once
    more after stopping.
    """
    os.environ.setdefault("ZENOH_RUNTIME", ZENOH_RUNTIME)  # before the first session opens
    from fleetlink.edge.admin import EdgeAdmin, load_token
    from fleetlink.edge.agent import EdgeAgent
    from fleetlink.edge.config import EdgeConfig

    config = load_service(EdgeConfig, "edge", args)
    # the admin API (HTTP when admin.listen is set, and the Zenoh admin space) with the changes
    # operators made at runtime, saved beside the spool and applied on top of the file
    token = load_token()
    admin = EdgeAdmin(config, token=token, extensions=console_extensions(token, config.edge_id))
    agent = EdgeAgent(admin.load(), options_from_args(args), stop_timeout_s=args.stop_timeout)
    done = threading.Event()

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        log.info("signal %d: stopping", signum)
        done.set()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGTERM, signal.SIGINT)}
    try:
        agent.start()
        admin.attach(agent)
        if admin.http is not None:
            log.info("admin API and console on %s", admin.url)
        while not done.wait(args.stats_interval):
            if args.stats_file is not None:
                write_stats(args.stats_file, agent.snapshot())
    finally:
        admin.stop()
        agent.stop()
        if args.stats_file is not None:
            write_stats(args.stats_file, agent.snapshot())
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return 0
