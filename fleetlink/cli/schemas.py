"""``fleetlink schemas ...``: print Avro schemas and type hashes, export ``.avsc`` files."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fleetlink.schemas.errors import SchemaError
from fleetlink.schemas.typestore import DISTROS, Distro, normalize_typename

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore


def register(subparsers: Any) -> None:
    """Add ``fleetlink schemas`` (``avro``, ``hash``, ``export``) to the subcommands."""
    parser = subparsers.add_parser(
        "schemas",
        help="ROS 2 types -> Avro schemas and RIHS01 type hashes",
        description="Derive Avro schemas and RIHS01 type hashes from ROS 2 message definitions.",
    )
    sub = parser.add_subparsers(dest="schemas_command", metavar="COMMAND", required=True)

    avro = sub.add_parser("avro", help="print the Avro schema (JSON) of a message type")
    avro.add_argument("type", metavar="TYPE", help="message type, e.g. sensor_msgs/msg/Imu")
    _add_store_arguments(avro)
    avro.set_defaults(handler=_avro)

    hashes = sub.add_parser("hash", help="print the RIHS01 type hash of a message or service type")
    hashes.add_argument("type", metavar="TYPE", help="e.g. std_msgs/msg/String or pkg/srv/Name")
    _add_store_arguments(hashes)
    hashes.set_defaults(handler=_hash)

    export = sub.add_parser("export", help="write .avsc files (one per type) for code generators")
    export.add_argument("--out", required=True, type=Path, metavar="DIR", help="output directory")
    export.add_argument("types", nargs="+", metavar="TYPE")
    _add_store_arguments(export)
    export.set_defaults(handler=_export)


def _add_store_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--msg-path",
        action="append",
        default=[],
        type=Path,
        metavar="DIR",
        help="ROS package folder with msg/*.msg and srv/*.srv (repeatable)",
    )
    parser.add_argument(
        "--bag", action="append", default=[], type=Path, metavar="PATH", help="take definitions from a bag"
    )
    parser.add_argument("--distro", choices=DISTROS, default="jazzy", help="ROS 2 distro (default: jazzy)")


def _store(args: argparse.Namespace) -> tuple[Typestore, Distro]:
    from fleetlink.schemas.typestore import load_typestore

    distro: Distro = args.distro
    return load_typestore(distro, args.msg_path, args.bag), distro


def _avro(args: argparse.Namespace) -> int:
    from fleetlink.schemas.avro_schema import avro_schema

    ts, distro = _store(args)
    print(json.dumps(avro_schema(ts, normalize_typename(args.type), distro), indent=2))
    return 0


def _hash(args: argparse.Namespace) -> int:
    from fleetlink.schemas.typehash import type_hash

    ts, distro = _store(args)
    print(type_hash(ts, normalize_typename(args.type), distro))
    return 0


def _export(args: argparse.Namespace) -> int:
    from fleetlink.schemas.avro_schema import avro_fullname, avro_schema

    ts, distro = _store(args)
    out: Path = args.out
    schemas = {}
    for name in args.types:
        typename = normalize_typename(name)
        schemas[avro_fullname(typename)] = avro_schema(ts, typename, distro)
    try:
        out.mkdir(parents=True, exist_ok=True)
        for fullname, schema in schemas.items():
            path = out / f"{fullname}.avsc"
            path.write_text(json.dumps(schema, indent=2) + "\n", encoding="utf-8")
            print(path)
    except OSError as exc:
        raise SchemaError(f"cannot write to {out}: {exc}") from exc
    sys.stdout.flush()
    return 0
