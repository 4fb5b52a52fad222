"""``fleetlink kafka read TOPIC``: the records of Kafka topics as JSON lines, Avro values decoded.

Where a robot integrator checks that records arrived, without another tool: each record is one
JSON object (topic, partition, offset, timestamp in ms, key, value); values in the Confluent
wire format are decoded with the schema registry, others shown as text (or hex when not UTF-8).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import uuid
from typing import Any, TextIO

DEFAULT_BOOTSTRAP = "127.0.0.1:9092"
DEFAULT_REGISTRY = "http://127.0.0.1:8081/apis/ccompat/v7"


def register(sub: Any) -> None:
    parser: argparse.ArgumentParser = sub.add_parser(
        "kafka", help="read the records fleetlink wrote to Kafka", description="Kafka, seen from fleetlink."
    )
    actions = parser.add_subparsers(dest="kafka_command", metavar="COMMAND", required=True)
    read = actions.add_parser(
        "read",
        help="print the records of Kafka topics as JSON lines (Avro values decoded)",
        description="Print records as JSON lines: topic, partition, offset, timestamp (ms), key, value.",
    )
    read.add_argument("topics", nargs="+", metavar="TOPIC")
    read.add_argument(
        "--bootstrap",
        default=os.environ.get("KAFKA_BOOTSTRAP", DEFAULT_BOOTSTRAP),
        help="Kafka (default $KAFKA_BOOTSTRAP, else %(default)s)",
    )
    read.add_argument(
        "--registry",
        default=os.environ.get("SCHEMA_REGISTRY_URL", DEFAULT_REGISTRY),
        help="schema registry, Confluent API (default $SCHEMA_REGISTRY_URL, else %(default)s)",
    )
    read.add_argument(
        "--from",
        dest="start",
        choices=["earliest", "latest"],
        default="earliest",
        help="start at the oldest record (default) or at new ones only",
    )
    read.add_argument("--key", help="only records with this key (e.g. a robot)")
    read.add_argument("--count", type=int, metavar="N", help="stop after N records")
    read.add_argument(
        "--timeout",
        type=float,
        metavar="S",
        help="stop after S seconds; exit 1 if --count records had not come by then",
    )
    read.set_defaults(handler=read_command)


def record_json(where: tuple[str, int, int], timestamp_ms: int, key: bytes | None, value: Any) -> str:
    """One record as a JSON line; ``where`` is (topic, partition, offset). Pure."""
    topic, partition, offset = where
    entry = {"topic": topic, "partition": partition, "offset": offset, "timestamp": timestamp_ms}
    return json.dumps({**entry, "key": _text(key), "value": value}, default=_plain, ensure_ascii=False)


def _text(raw: bytes | None) -> str | None:
    if raw is None:
        return None
    try:
        return raw.decode()
    except UnicodeDecodeError:
        return raw.hex()


def _plain(value: Any) -> Any:
    if isinstance(value, bytes | bytearray):
        return list(value)
    raise TypeError(f"{type(value).__name__} is not JSON")


def read_command(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    from confluent_kafka import Consumer
    from confluent_kafka.schema_registry import SchemaRegistryClient
    from confluent_kafka.schema_registry.avro import AvroDeserializer
    from confluent_kafka.serialization import MessageField, SerializationContext

    decode = AvroDeserializer(SchemaRegistryClient({"url": args.registry}))
    consumer = Consumer(
        {
            "bootstrap.servers": args.bootstrap,
            "group.id": f"fleetlink-read-{uuid.uuid4().hex[:8]}",
            "auto.offset.reset": args.start,
            "enable.auto.commit": False,
            "log_level": 3,
        }
    )
    deadline = None if args.timeout is None else time.monotonic() + args.timeout
    printed = 0
    try:
        consumer.subscribe(list(args.topics))
        while args.count is None or printed < args.count:
            if deadline is not None and time.monotonic() >= deadline:
                break
            msg = consumer.poll(0.2)
            if msg is None or msg.error() is not None:
                continue
            key = msg.key()
            if args.key is not None and _text(key) != args.key:
                continue
            raw = msg.value()
            value: Any = None
            if raw is not None and raw[:1] == b"\x00":
                try:
                    value = decode(raw, SerializationContext(msg.topic() or "", MessageField.VALUE))
                except Exception as exc:  # noqa: BLE001 - any decoder failure: show the bytes and why
                    value = {"undecoded": raw.hex(), "error": f"{type(exc).__name__}: {exc}"}
            elif raw is not None:
                value = _text(raw)
            where = (msg.topic() or "", msg.partition() or 0, msg.offset() or 0)
            line = record_json(where, msg.timestamp()[1], key, value)
            print(line, file=out, flush=True)
            printed += 1
    finally:
        consumer.close()
    if args.count is not None and printed < args.count:
        print(f"{printed} of {args.count} record(s) within {args.timeout:g} s", file=sys.stderr)
        return 1
    return 0
