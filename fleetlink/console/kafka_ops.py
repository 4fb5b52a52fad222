"""The fleet console's operations through Kafka: the dead-letter browser and sending commands.

- ``KafkaDeadLetters``: the newest dead letters from a ``KafkaTail`` of the dead-letter topic,
  with the headers the edge and the uplink put on them (site, edge, stage, reason, where the
  record was going) and the raw bytes as hex;
- ``KafkaCommands``: a command is a record on a command mapping's ``from`` topic, keyed by the
  robot, its value Avro in the Confluent wire format (the schema registered for the topic's
  ``-value`` subject, or, when none is, the one fleetlink derives from the mapping's ROS type),
  with the ``fleetlink-command-id`` header, exactly as a stream-processing app writes one; the
  uplinks' command router takes it from there. Its statuses come from a ``KafkaTail`` of the
  command status topic (``delivered``, ``superseded``, ``expired``, ``rejected``).

The value an operator types is completed with each field's default (``fill_datum``, pure), so
``{override_system: true}`` is enough for a message with many fields.
"""

from __future__ import annotations

import contextlib
import io
import json
import threading
import time
import uuid
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import fastavro
from confluent_kafka import KafkaError, KafkaException, Producer

from fleetlink.console.kafka_tail import KafkaTail, TailRecord
from fleetlink.console.operations import CommandRefusedError
from fleetlink.schemas.errors import SchemaError
from fleetlink.schemas.single_object import confluent_frame
from fleetlink.uplink.calls.plan import CORRELATION_HEADER, GOAL_HEADER
from fleetlink.uplink.commands.plan import COMMAND_ID_HEADER

HEX_BYTES = 4096
ID_HEADERS = {"command": COMMAND_ID_HEADER, "service": CORRELATION_HEADER, "action": GOAL_HEADER}
"""The header that names a record of each kind of mapping (what its statuses are found by)."""
VALUE_SUFFIXES = {"command": "", "service": "_Request", "action": "_Goal"}
"""What a record of each kind holds: the command's message, the service's request, the goal."""

_PRIMITIVE_DEFAULTS: dict[str, Any] = {
    "null": None,
    "boolean": False,
    "int": 0,
    "long": 0,
    "float": 0.0,
    "double": 0.0,
    "bytes": b"",
    "string": "",
}


def named_types(schema: Any, found: dict[str, Any] | None = None, namespace: str = "") -> dict[str, Any]:
    """Every named type a schema defines, by name and full name (later uses refer to them by name)."""
    found = {} if found is None else found
    if isinstance(schema, list):
        for branch in schema:
            named_types(branch, found, namespace)
    elif isinstance(schema, dict):
        kind = schema.get("type")
        if kind in ("record", "enum", "fixed") and isinstance(schema.get("name"), str):
            name = schema["name"]
            space = schema.get("namespace", namespace) if "." not in name else name.rpartition(".")[0]
            full = name if "." in name else f"{space}.{name}" if space else name
            found[full] = found[name.rpartition(".")[2]] = schema
            namespace = space
        if kind == "record":
            for f in schema.get("fields", ()):
                named_types(f.get("type"), found, namespace)
        elif kind == "array":
            named_types(schema.get("items"), found, namespace)
        elif kind == "map":
            named_types(schema.get("values"), found, namespace)
        elif isinstance(kind, dict | list):
            named_types(kind, found, namespace)
    return found


def fill_datum(  # noqa: PLR0911, PLR0912 - one branch per Avro kind
    schema: Any, value: Any, path: str = "", names: dict[str, Any] | None = None
) -> Any:
    """``value`` completed with defaults for ``schema`` (a parsed-JSON Avro schema); raises
    ``CommandRefusedError`` naming the field that does not fit."""
    names = named_types(schema) if names is None else names
    where = path or "<value>"
    if isinstance(schema, list):  # a union: null when not given, else the first branch that takes it
        if value is None and "null" in schema:
            return None
        for branch in schema:
            if branch == "null":
                continue
            try:
                return fill_datum(branch, value, path, names)
            except CommandRefusedError:
                continue
        raise CommandRefusedError(f"{where}: {value!r} fits none of {schema}")
    if isinstance(schema, str):
        if schema in _PRIMITIVE_DEFAULTS:
            return _primitive(schema, value, where)
        if schema in names:
            return fill_datum(names[schema], value, path, names)
        raise CommandRefusedError(f"{where}: unknown type {schema}")
    kind = schema.get("type")
    if kind == "record":
        given = value if value is not None else {}
        if not isinstance(given, Mapping):
            raise CommandRefusedError(f"{where}: a mapping of fields is expected")
        fields = {f["name"] for f in schema["fields"]}
        unknown = sorted(set(given) - fields)
        if unknown:
            raise CommandRefusedError(
                f"{path + '.' if path else ''}{unknown[0]}: not a field of {schema['name']}"
            )
        out = {}
        for f in schema["fields"]:
            sub = f"{path}.{f['name']}" if path else f["name"]
            if f["name"] in given:
                out[f["name"]] = fill_datum(f["type"], given[f["name"]], sub, names)
            elif "default" in f:
                out[f["name"]] = f["default"]
            else:
                out[f["name"]] = fill_datum(f["type"], None, sub, names)
        return out
    if kind == "array":
        items = value if value is not None else []
        if not isinstance(items, list):
            raise CommandRefusedError(f"{where}: a list is expected")
        return [fill_datum(schema["items"], v, f"{path}[{i}]", names) for i, v in enumerate(items)]
    if kind == "fixed":
        size = int(schema["size"])
        data = value if isinstance(value, bytes) else b"\0" * size if value is None else None
        if data is None or len(data) != size:
            raise CommandRefusedError(f"{where}: {size} bytes expected")
        return data
    if kind == "enum":
        if value is None:
            return schema.get("default", schema["symbols"][0])
        if value not in schema["symbols"]:
            raise CommandRefusedError(f"{where}: one of {schema['symbols']} expected")
        return value
    if isinstance(kind, str) and kind in _PRIMITIVE_DEFAULTS:
        return _primitive(kind, value, where)
    if isinstance(kind, dict | list) or (isinstance(kind, str) and kind in names):
        return fill_datum(kind, value, path, names)
    raise CommandRefusedError(f"{where}: Avro type {kind!r} is not supported here")


def _primitive(kind: str, value: Any, where: str) -> Any:
    if value is None:
        return _PRIMITIVE_DEFAULTS[kind]
    ok = {
        "null": value is None,
        "boolean": isinstance(value, bool),
        "int": isinstance(value, int) and not isinstance(value, bool) and -(2**31) <= value < 2**31,
        "long": isinstance(value, int) and not isinstance(value, bool),
        "float": isinstance(value, int | float) and not isinstance(value, bool),
        "double": isinstance(value, int | float) and not isinstance(value, bool),
        "bytes": isinstance(value, bytes | str),
        "string": isinstance(value, str),
    }[kind]
    if not ok:
        raise CommandRefusedError(f"{where}: {value!r} is not a valid {kind}")
    if kind in ("float", "double"):
        return float(value)
    if kind == "bytes" and isinstance(value, str):
        return value.encode()
    return value


def dead_letter_view(record: TailRecord) -> dict[str, Any]:
    """One dead letter for the browser (pure)."""
    return {
        "partition": record.partition,
        "offset": record.offset,
        "timestamp_ms": record.timestamp_ms,
        "key": (record.key or b"").decode("utf-8", "replace"),
        "site": record.header("fleetlink.site"),
        "edge": record.header("fleetlink.edge"),
        "topic": record.header("fleetlink.dlq.topic"),
        "stage": record.header("fleetlink.dlq.stage"),
        "reason": record.header("fleetlink.dlq.reason"),
        "source_topic": record.header("fleetlink.source_topic") or record.header("fleetlink.ros.topic"),
        "size": len(record.value),
        "value_hex": record.value[:HEX_BYTES].hex(),
        "truncated": len(record.value) > HEX_BYTES,
    }


class KafkaDeadLetters:
    """The dead-letter browser on a ``KafkaTail`` of the dead-letter topic."""

    def __init__(self, tail: KafkaTail) -> None:
        self.tail = tail

    def recent(self, site: str | None, limit: int) -> list[dict[str, Any]]:
        """The newest ``limit`` dead letters kept, newest first, of ``site`` (``None``: every site)."""
        found = [r for r in self.tail.records() if site is None or r.header("fleetlink.site") == site]
        return [dead_letter_view(r) for r in found[:limit]]

    def raw(self, partition: int, offset: int) -> bytes | None:
        """The value of the dead letter at ``partition`` and ``offset`` (``None``: not among those kept)."""
        found = self.tail.find(partition, offset)
        return None if found is None else found.value


class StatusBook:
    """Status records by command id, the newest ``keep`` commands (fed by a ``KafkaTail``). A book
    of call outcomes (replies, goal results) keys them by ``id_field`` (``correlation_id``,
    ``goal_id``) instead. Status records are at-least-once (docs/commands.md): a second record of
    the same ``(command id, status, site, robot)`` is the first sent again, and is kept once."""

    def __init__(
        self, decode: Callable[[bytes], dict[str, Any]], *, keep: int = 2000, id_field: str = "command_id"
    ) -> None:
        self._decode = decode
        self.keep = keep
        self.id_field = id_field
        self._by_id: OrderedDict[str, list[dict[str, Any]]] = OrderedDict()
        self._lock = threading.Lock()

    def on_record(self, record: TailRecord) -> None:
        """Add one status record to its command's list; the command least recently heard of beyond
        ``keep`` is forgotten."""
        datum = self._decode(record.value)
        command_id = str(datum.get(self.id_field, ""))
        entry = {
            "status": str(datum.get("status", "")),
            "site": str(datum.get("site", "")),
            "detail": str(datum.get("detail", "")),
            "at_ms": datum.get("at") if isinstance(datum.get("at"), int) else record.timestamp_ms,
            "robot": str(datum.get("robot", "")),
        }
        same = (entry["status"], entry["site"], entry["robot"])
        with self._lock:
            entries = self._by_id.setdefault(command_id, [])
            if not any((e["status"], e["site"], e["robot"]) == same for e in entries):
                entries.append(entry)  # status records are at-least-once: a record sent again is shown once
            self._by_id.move_to_end(command_id)
            while len(self._by_id) > self.keep:
                self._by_id.popitem(last=False)

    def of(self, command_ids: Sequence[str]) -> dict[str, list[dict[str, Any]]]:
        """The status entries of each command id, oldest first (none for an unknown id)."""
        with self._lock:
            return {c: list(self._by_id.get(c, ())) for c in command_ids}


class KafkaCommands:
    """Sends the console's commands, service calls and action goals as records on their mappings'
    Kafka topics; their statuses come from ``StatusBook``s (the command status topic, the replies
    and results topics)."""

    def __init__(
        self,
        producer_config: Mapping[str, Any],
        mappings: Sequence[Mapping[str, Any]],
        *,
        schema_for: Callable[[str, str], dict[str, Any]],
        register: Callable[[str, dict[str, Any]], int],
        statuses: StatusBook | Sequence[StatusBook],
        robots: Callable[[], Sequence[str]],
        timeout_s: float = 10.0,
    ) -> None:
        """``mappings``: ``{name, from, to, type}`` and ``kind`` (``command``, the default,
        ``service`` or ``action``); ``schema_for(topic, ros_type)`` the value schema to write with;
        ``register(subject, schema)`` its registry id; ``robots()`` the robots the registrations
        topic knows."""
        self._mappings = {str(m["name"]): dict(m) for m in mappings}
        self._producer = Producer({**producer_config, "linger.ms": 0})
        self._schema_for = schema_for
        self._register = register
        self._books = [statuses] if isinstance(statuses, StatusBook) else list(statuses)
        self._robots = robots
        self.timeout_s = timeout_s
        self._lock = threading.Lock()

    def mappings(self) -> list[dict[str, Any]]:
        """The command mappings an operator may use: name, from, to, type, robot, broadcast."""
        return [
            {
                k: m.get(k, "command" if k == "kind" else None)
                for k in ("name", "kind", "from", "to", "type", "robot", "broadcast")
            }
            for m in self._mappings.values()
        ]

    def send(self, mapping: str, robot: str, value: Any, *, user: str) -> dict[str, Any]:
        """Produce one command for ``robot`` through ``mapping`` and wait for Kafka's acknowledgement;
        returns its id, topic, partition and offset.

        Raises ``CommandRefusedError`` for an unknown mapping or robot, a value that does not fit,
        no schema, or a record Kafka refused or did not acknowledge within ``timeout_s``.
        """
        found = self._mappings.get(mapping)
        if found is None:
            raise CommandRefusedError(f"no command mapping named {mapping!r}")
        known = set(self._robots())
        if robot not in known:
            raise CommandRefusedError(f"robot {robot!r} is not registered at any site")
        kind = str(found.get("kind", "command"))
        topic, ros_type = str(found["from"]), str(found["type"]) + VALUE_SUFFIXES[kind]
        try:
            schema = self._schema_for(topic, ros_type)
            schema_id = self._register(f"{topic}-value", schema)
        except SchemaError as exc:
            raise CommandRefusedError(f"no schema for {ros_type} on {topic}: {exc}") from None
        datum = fill_datum(schema, value)
        body = io.BytesIO()
        try:
            fastavro.schemaless_writer(body, fastavro.parse_schema(json.loads(json.dumps(schema))), datum)
        except (ValueError, TypeError) as exc:
            raise CommandRefusedError(f"the value does not fit {ros_type}: {exc}") from None
        # a goal's id is a UUID (the action protocol's); commands and calls get a readable one
        command_id = str(uuid.uuid4()) if kind == "action" else f"console-{uuid.uuid4().hex[:12]}"
        delivered: list[Any] = []
        done = threading.Event()

        def report(err: Any, msg: Any) -> None:
            delivered.append((err, msg))
            done.set()

        with self._lock:
            try:
                self._producer.produce(
                    topic,
                    key=robot.encode(),
                    value=confluent_frame(schema_id, body.getvalue()),
                    headers=[
                        (ID_HEADERS[kind], command_id.encode()),
                        ("fleetlink-console-user", user.encode()),
                    ],
                    timestamp=int(time.time() * 1000),
                    on_delivery=report,
                )
                self._producer.flush(self.timeout_s)
                if not done.is_set():  # not sent yet (Kafka unreachable): taken back, never sent later
                    self._producer.purge(in_queue=True, in_flight=False)
                    self._producer.poll(0)
            except (BufferError, KafkaException) as exc:  # too large, queue full, producer failed
                raise CommandRefusedError(f"Kafka refused the command: {exc}") from None
        if not done.is_set():  # sent, unanswered: the broker may still write it
            raise CommandRefusedError(
                f"Kafka did not acknowledge command {command_id} within {self.timeout_s:g} s; it was "
                "sent and may still be written: look for its status before sending it again"
            )
        err, msg = delivered[0]
        if err is not None and err.code() == KafkaError._PURGE_QUEUE:
            raise CommandRefusedError(f"Kafka not reached within {self.timeout_s:g} s: command not sent")
        if err is not None:
            raise CommandRefusedError(f"Kafka refused the command: {err}")
        return {
            "command_id": command_id,
            "mapping": mapping,
            "robot": robot,
            "topic": topic,
            "partition": msg.partition(),
            "offset": msg.offset(),
        }

    def statuses(self, command_ids: list[str]) -> dict[str, list[dict[str, Any]]]:
        """The status records of these commands, calls and goals, oldest first."""
        out: dict[str, list[dict[str, Any]]] = {c: [] for c in command_ids}
        for book in self._books:
            for command_id, entries in book.of(command_ids).items():
                out[command_id].extend(entries)
        for entries in out.values():
            entries.sort(key=lambda e: e["at_ms"] if isinstance(e["at_ms"], int) else 0)
        return out

    def close(self) -> None:
        """Flush and drop the producer (the console is stopping)."""
        with self._lock, contextlib.suppress(KafkaException):  # failed for good: nothing to flush
            self._producer.flush(self.timeout_s)
