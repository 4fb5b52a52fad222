"""``fleetlink zenoh render`` and ``fleetlink zenoh router``: concrete router configs, and a router.

``render`` fills in a template of ``deploy/zenoh/`` and writes a file that stock ``zenohd``
(``zenohd -c FILE``) and ``fleetlink zenoh router -c FILE`` read; the file starts with the
command that wrote it. ``router`` runs a Zenoh router (zenohd's core, in this process) from a
concrete config until SIGTERM or Ctrl-C, for machines without zenohd.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from typing import Any

from fleetlink.cli.logs import SERVICE_VERBOSITY
from fleetlink.common.errors import ConfigError


def register(sub: Any) -> None:
    """Add ``fleetlink zenoh render`` and ``fleetlink zenoh router`` to the subcommands."""
    parser: argparse.ArgumentParser = sub.add_parser(
        "zenoh",
        help="Zenoh router configs: render a template of deploy/zenoh, run a router",
        description="Write concrete Zenoh router configs from the templates in deploy/zenoh/, or run "
        "a Zenoh router from one.",
    )
    actions = parser.add_subparsers(dest="zenoh_command", metavar="COMMAND", required=True)

    render = actions.add_parser(
        "render",
        help="fill in a router template (${SITE}, ${LISTEN} …) and write a concrete config",
        description="Fill in the placeholders of a router template and write a config zenohd reads. "
        "Per-site ACL entries (--acl-site) and raw topics are generated as in "
        "fleetlink.common.zenoh_configs.",
    )
    render.add_argument("template", type=Path, help="a template, e.g. deploy/zenoh/edge-router.json5")
    render.add_argument("--site", help="${SITE}: the site name (edge templates)")
    render.add_argument("-l", "--listen", action="append", default=[], metavar="ENDPOINT", help="${LISTEN}")
    render.add_argument("-e", "--connect", action="append", default=[], metavar="ENDPOINT", help="${CONNECT}")
    render.add_argument(
        "--cert-dir", metavar="DIR", help="${CERT_DIR}: the folder of ca.pem and the router's keys"
    )
    render.add_argument(
        "--acl-site",
        action="append",
        default=[],
        metavar="SITE",
        help="cloud template: let the edge of SITE (certificate edge-SITE) act on fleetlink/SITE/** "
        "(repeatable)",
    )
    render.add_argument(
        "--raw-to-cloud",
        action="append",
        default=[],
        metavar="KEY",
        help="edge template: let this raw ROS key cross the WAN, downsampled (repeatable)",
    )
    render.add_argument("-o", "--output", type=Path, metavar="FILE", help="write here (default: stdout)")
    render.set_defaults(handler=render_command)

    router = actions.add_parser(
        "router",
        help="run a Zenoh router from a concrete config (like zenohd -c FILE)",
        description="Run a Zenoh router (zenohd's core in this process) until SIGTERM or Ctrl-C.",
    )
    router.add_argument("-c", "--config", type=Path, required=True, metavar="FILE", help="concrete config")
    router.add_argument(
        "-l", "--listen", action="append", default=[], metavar="ENDPOINT", help="listen here instead"
    )
    router.add_argument(
        "-e", "--connect", action="append", default=[], metavar="ENDPOINT", help="connect here instead"
    )
    router.add_argument(
        "--cfg", action="append", default=[], metavar="KEY:JSON5", help="config override (repeatable)"
    )
    router.set_defaults(handler=router_command, log_verbosity=SERVICE_VERBOSITY)


def render_command(args: argparse.Namespace) -> int:
    """Fill in a router template and write it to ``--output`` (or standard output); returns 0."""
    from fleetlink.common.zenoh_configs import concrete_json5

    try:
        text = args.template.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{args.template}: cannot read the template: {exc.strerror}") from None
    header = (
        f"// Rendered from {args.template} by:\n//   {render_command_line(args)}\n"
        "// Change the template or the command and render again; do not edit by hand.\n"
    )
    out = concrete_json5(
        text,
        source=str(args.template),
        header=header,
        site=args.site,
        listen=args.listen,
        connect=args.connect,
        cert_dir=args.cert_dir,
        sites=args.acl_site,
        raw_to_cloud=args.raw_to_cloud,
    )
    if args.output is None:
        sys.stdout.write(out)
        return 0
    try:
        args.output.parent.mkdir(parents=True, exist_ok=True)
        args.output.write_text(out, encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{args.output}: cannot write: {exc.strerror}") from None
    print(args.output)
    return 0


def render_command_line(args: argparse.Namespace) -> str:
    """The ``fleetlink zenoh render`` command that makes the same file (written into its header)."""
    argv = ["fleetlink", "zenoh", "render", str(args.template)]
    if args.site:
        argv += ["--site", args.site]
    argv += [a for e in args.listen for a in ("-l", e)]
    argv += [a for e in args.connect for a in ("-e", e)]
    if args.cert_dir:
        argv += ["--cert-dir", args.cert_dir]
    argv += [a for s in args.acl_site for a in ("--acl-site", s)]
    argv += [a for k in args.raw_to_cloud for a in ("--raw-to-cloud", k)]
    if args.output is not None:
        argv += ["-o", str(args.output)]
    return shlex.join(argv)


def router_command(args: argparse.Namespace) -> int:
    """Run a Zenoh router from a concrete config until SIGTERM or Ctrl-C; returns 0."""
    from fleetlink.cli.service import wait_for_stop
    from fleetlink.common.zenoh_options import ZenohOptions, load_zenoh_file
    from fleetlink.roswire.session import open_session

    load_zenoh_file(args.config)  # a template or a file Zenoh refuses fails here, by name
    overrides = []
    for item in args.cfg:
        key, sep, value = item.partition(":")
        if not sep or not key:
            raise ConfigError(f"--cfg {item!r}: expected KEY:JSON5_VALUE")
        overrides.append((key, value))
    options = ZenohOptions(
        mode="router",
        connect=tuple(args.connect),
        listen=tuple(args.listen),
        config_file=args.config,
        overrides=tuple(overrides),
    )
    conf = options.to_config()
    session = open_session(conf)
    try:
        listening = ", ".join(_endpoints(conf)) or "nothing"
        print(f"zenoh router {session.info.zid()} running: listening on {listening}", flush=True)
        wait_for_stop()
    finally:
        session.close()
    return 0


def _endpoints(conf: Any) -> list[str]:
    import json

    value = json.loads(conf.get_json("listen/endpoints"))
    if isinstance(value, dict):  # mode-dependent: {"router": [...], "peer": [...]}
        value = value.get("router", [])
    return [str(e) for e in value]
