"""``fleetlink kafka echo|send``: read and write Avro records on the command line, through the registry.

``echo TOPIC`` prints one JSON object per record (topic, partition, offset, timestamp, key,
headers, schema id, value decoded with its writer schema); ``send TOPIC --key K 'YAML'`` encodes
a YAML (or JSON) value with the latest schema registered under ``TOPIC-value`` and produces it.
Like kcat and kafka-console-consumer: ``-b/--bootstrap`` and ``--registry`` (else the
``KAFKA_BOOTSTRAP`` / ``SCHEMA_REGISTRY_URL`` variables, else the stack of ``fleetlink stack up``),
data on stdout, messages on stderr; exit 0, 1 on errors, 2 on usage errors, 130 on Ctrl-C.
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import sys
import time
import uuid
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fleetlink.common.errors import ConfigError, FleetlinkError
from fleetlink.localstack.stack import StackInfo
from fleetlink.schemas.registry_urls import APICURIO_CCOMPAT_PATH, APICURIO_NATIVE_PATH

if TYPE_CHECKING:
    from confluent_kafka import Message

    from fleetlink.schemas.confluent_values import ConfluentValues

STACK_DIR = Path("var/stack")
DELIVERY_TIMEOUT_S = 30.0


class KafkaCliError(FleetlinkError):
    """A topic that does not exist, a record that was not delivered."""


def register(sub: Any) -> None:
    """Add ``fleetlink kafka echo`` and ``fleetlink kafka send`` to the subcommands."""
    parser: argparse.ArgumentParser = sub.add_parser(
        "kafka",
        help="read and write Avro records on Kafka topics, decoded and encoded through the registry",
        description="Read records as JSON (echo) or write one from YAML (send); values are Avro in the "
        "Confluent wire format, schemas from the registry.",
    )
    actions = parser.add_subparsers(dest="kafka_command", metavar="ACTION", required=True)

    echo = actions.add_parser(
        "echo",
        help="print records as JSON lines: key, headers, timestamp, value",
        description="Print each record as one JSON object: topic, partition, offset, timestamp (ms), "
        "key, headers, schema_id and value (decoded with its writer schema; bytes as base64, non-finite "
        'floats as "NaN"/"Infinity"/"-Infinity"). A value that does not decode is shown as '
        "value_base64 with an error. By default it waits for new records (Ctrl-C stops it); with "
        "--from-beginning it prints what the topic holds and stops at its end.",
    )
    echo.add_argument("topic", metavar="TOPIC")
    _add_places(echo)
    echo.add_argument("-n", "--max-records", type=int, metavar="N", help="stop after N records")
    echo.add_argument(
        "--from-beginning", action="store_true", help="start at the oldest record (default: only new ones)"
    )
    echo.add_argument(
        "-f",
        "--follow",
        action="store_true",
        help="with --from-beginning: keep waiting for new records at the end (the default without it); "
        "a topic that does not exist yet is waited for",
    )
    echo.set_defaults(handler=_echo)

    send = actions.add_parser(
        "send",
        help="encode a YAML value with the topic's latest schema and produce it",
        description="Encode VALUE (YAML or JSON; '-' reads stdin) with the latest schema registered under "
        "TOPIC-value and produce it (acks=all). bytes fields take base64 text or a list of 0-255 "
        "integers; float fields also take NaN, Infinity, -Infinity; a missing field takes its default "
        "if it has one. Example: fleetlink kafka send fleet.commands.lightring --key tb4_02 "
        "\"{header: {stamp: {sec: 0, nanosec: 0}, frame_id: ''}, leds: [...], override_system: true}\"",
    )
    send.add_argument("topic", metavar="TOPIC")
    send.add_argument("value", metavar="VALUE", help="the record value as YAML or JSON, or - for stdin")
    send.add_argument("-k", "--key", help="the record key (UTF-8), e.g. the robot")
    send.add_argument(
        "-H",
        "--header",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a header (repeatable), e.g. fleetlink-command-id=tb4_02-red-1",
    )
    send.add_argument("--timestamp", type=int, metavar="MS", help="record timestamp in ms (default: now)")
    _add_places(send)
    send.set_defaults(handler=_send)


def _add_places(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "-b", "--bootstrap", metavar="HOST:PORT", help="Kafka bootstrap servers (default: $KAFKA_BOOTSTRAP)"
    )
    parser.add_argument(
        "--registry",
        metavar="URL",
        help="Confluent-compatible schema registry URL, for Apicurio http://HOST:PORT/apis/ccompat/v7 "
        "(default: $SCHEMA_REGISTRY_URL)",
    )


def places(
    bootstrap: str | None, registry: str | None, env: dict[str, str], stack: StackInfo | None
) -> tuple[str, str]:
    """Kafka and the registry: the options, else the environment, else a local stack's; or ConfigError."""
    bootstrap = bootstrap or env.get("KAFKA_BOOTSTRAP") or (stack.bootstrap if stack else None)
    registry = registry or env.get("SCHEMA_REGISTRY_URL") or (stack.registry_url if stack else None)
    if not bootstrap or not registry:
        missing = " and ".join(
            what
            for what, value in (
                ("-b/--bootstrap (or KAFKA_BOOTSTRAP)", bootstrap),
                ("--registry (or SCHEMA_REGISTRY_URL)", registry),
            )
            if not value
        )
        raise ConfigError(f"give {missing}; no `fleetlink stack up` stack runs under {STACK_DIR} either")
    if APICURIO_NATIVE_PATH in registry:
        ccompat = registry.split(APICURIO_NATIVE_PATH)[0] + APICURIO_CCOMPAT_PATH
        raise ConfigError(
            f"--registry {registry} is Apicurio's native API; this command speaks the Confluent-compatible "
            f"one: --registry {ccompat}"
        )
    return bootstrap, registry


def _places(args: argparse.Namespace) -> tuple[str, str]:
    return places(args.bootstrap, args.registry, dict(os.environ), StackInfo.load(STACK_DIR))


# --- echo ---------------------------------------------------------------------------------


def text_or_base64(raw: bytes | None) -> str | dict[str, str] | None:
    """UTF-8 text as a string; other bytes as ``{"base64": ...}``; None stays None."""
    if raw is None:
        return None
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return {"base64": base64.b64encode(raw).decode("ascii")}


def headers_json(headers: Iterable[tuple[str, bytes | None]] | None) -> dict[str, Any]:
    """Headers as an object; a name that repeats maps to the list of its values, in order."""
    out: dict[str, Any] = {}
    for name, raw in headers or ():
        value = text_or_base64(raw)
        if name not in out:
            out[name] = value
        elif isinstance(out[name], list):
            out[name].append(value)
        else:
            out[name] = [out[name], value]
    return out


def record_json(message: Message, values: ConfluentValues) -> dict[str, Any]:
    """One record as the JSON object ``echo`` prints."""
    from fleetlink.schemas.avro_json import to_json
    from fleetlink.schemas.registry import RegistryUnavailableError

    kind, timestamp = message.timestamp()
    out: dict[str, Any] = {
        "topic": message.topic(),
        "partition": message.partition(),
        "offset": message.offset(),
        "timestamp": timestamp if kind else None,
        "key": text_or_base64(message.key()),
        "headers": headers_json(message.headers()),
    }
    raw = message.value()
    if raw is None:
        return {**out, "schema_id": None, "value": None}
    try:
        schema_id, datum = values.decode(raw)
    except RegistryUnavailableError:
        raise
    except FleetlinkError as exc:  # not Confluent-framed, an unknown schema id, a body that does not fit
        return {
            **out,
            "schema_id": None,
            "value": None,
            "value_base64": base64.b64encode(raw).decode(),
            "error": str(exc),
        }
    return {**out, "schema_id": schema_id, "value": to_json(datum)}


def _topic(consumer: Any, name: str) -> Any:
    """The topic's metadata, or None while it does not exist (or has no partitions yet)."""
    topic = consumer.list_topics(name, timeout=10).topics.get(name)
    if topic is None or topic.error is not None or not topic.partitions:
        return None
    return topic


def _echo(args: argparse.Namespace) -> int:
    from confluent_kafka import OFFSET_BEGINNING, OFFSET_END, Consumer, KafkaError, TopicPartition

    from fleetlink.schemas.confluent_values import ConfluentValues
    from fleetlink.schemas.registry import SchemaRegistry

    if args.max_records is not None and args.max_records < 1:
        print("fleetlink kafka echo: -n must be at least 1", file=sys.stderr)
        return 2
    bootstrap, registry_url = _places(args)
    follow = args.follow or not args.from_beginning
    consumer = Consumer(
        {
            "bootstrap.servers": bootstrap,
            "group.id": f"fleetlink-kafka-echo-{uuid.uuid4().hex[:8]}",  # never joined nor committed
            "enable.auto.commit": False,
            "enable.partition.eof": True,
            "log_level": 3,
        }
    )
    count = 0
    with SchemaRegistry(registry_url) as registry:
        values = ConfluentValues(registry.schema_by_id)
        try:
            topic = _topic(consumer, args.topic)
            while topic is None and follow:  # following: a topic made later (a first record) is waited for
                time.sleep(0.5)  # ok-sleep: polling the broker's metadata for the topic
                topic = _topic(consumer, args.topic)
            if topic is None:
                raise KafkaCliError(f"topic {args.topic!r} does not exist on {bootstrap}")
            start = OFFSET_BEGINNING if args.from_beginning else OFFSET_END
            consumer.assign([TopicPartition(args.topic, p, start) for p in sorted(topic.partitions)])
            at_end: set[int] = set()
            while follow or len(at_end) < len(topic.partitions):
                message = consumer.poll(0.2)
                if message is None:
                    continue
                error = message.error()
                if error is not None:
                    if error.code() == KafkaError._PARTITION_EOF:
                        at_end.add(message.partition())
                        continue
                    raise KafkaCliError(f"reading {args.topic}: {error}")
                print(json.dumps(record_json(message, values), ensure_ascii=False), flush=True)
                count += 1
                if args.max_records is not None and count >= args.max_records:
                    break
        except KeyboardInterrupt:
            pass  # Ctrl-C ends a follow: what was printed stands
        except BrokenPipeError:  # `| head`: the reader has what it wanted
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        finally:
            consumer.close()
    return 0


# --- send ---------------------------------------------------------------------------------


def parse_headers(specs: list[str]) -> list[tuple[str, bytes]]:
    """``NAME=VALUE`` options as Kafka headers (UTF-8 values); ConfigError on a spec without ``=``."""
    out = []
    for spec in specs:
        name, sep, value = spec.partition("=")
        if not sep or not name:
            raise ConfigError(f"--header {spec!r}: expected NAME=VALUE")
        out.append((name, value.encode()))
    return out


def parse_value(text: str) -> Any:
    """The value YAML (or JSON, a subset) describes; ConfigError naming the line on a syntax error."""
    import yaml

    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"VALUE is not valid YAML: {exc}") from None


def _send(args: argparse.Namespace) -> int:
    from confluent_kafka import KafkaException, Producer

    from fleetlink.schemas.avro_json import from_json
    from fleetlink.schemas.confluent_values import ConfluentValues
    from fleetlink.schemas.registry import SchemaRegistry, subject_for_topic

    headers = parse_headers(args.header)
    data = parse_value(sys.stdin.read() if args.value == "-" else args.value)
    bootstrap, registry_url = _places(args)
    subject = subject_for_topic(args.topic)
    with SchemaRegistry(registry_url) as registry:
        schema_id, version, schema = registry.latest(subject)
        value = ConfluentValues(registry.schema_by_id).encode(schema_id, schema, from_json(schema, data))
    delivered: list[Message] = []
    failures: list[str] = []

    def report(err: Any, message: Message) -> None:
        if err is not None:
            failures.append(str(err))
        else:
            delivered.append(message)

    producer = Producer(
        {"bootstrap.servers": bootstrap, "acks": "all", "enable.idempotence": True, "log_level": 3}
    )
    try:
        producer.produce(
            args.topic,
            key=None if args.key is None else args.key.encode(),
            value=value,
            headers=headers,
            timestamp=args.timestamp or 0,
            on_delivery=report,
        )
    except (KafkaException, BufferError) as exc:
        raise KafkaCliError(f"cannot produce to {args.topic}: {exc}") from exc
    producer.flush(DELIVERY_TIMEOUT_S)
    if failures or not delivered:
        reason = failures[0] if failures else f"no delivery report within {DELIVERY_TIMEOUT_S:.0f} s"
        raise KafkaCliError(f"record not delivered to {args.topic}: {reason}")
    message = delivered[0]
    print(
        f"sent to {args.topic} partition {message.partition()} offset {message.offset()}: key "
        f"{args.key!r}, schema id {schema_id} ({subject} version {version})"
    )
    return 0
