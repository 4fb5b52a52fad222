"""The fault-detection pipeline on Quix Streams: three sensor topics in, light-ring commands out.

::

    fleet.ir_intensity ─────┐  event → failure
    fleet.hazard_detection ─┼─ (rules.event_failure) ─ concat ─ sliding window per robot
    fleet.kidnap_status ────┘                                  (events, failures)
                                                                     │
    fleet.commands.lightring ◀─ Avro (registry) ◀─ command on change ◀┘
                                                   (state store: running/failed)

Records are read with the registry's writer schema (Confluent wire format, stock
deserializer); commands are written as ``irobot_create_msgs/msg/LightringLeds`` with the schema
derived from the ROS definition, registered under ``<commands topic>-value``. Windows use the
record timestamps (the ROS source stamps), so decisions follow event time, not arrival time.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

from fleetlink.common.extras import missing_extra
from fleetlink.examples.fault_detection.errors import BadRecordError, FaultDetectionError, SettingsError
from fleetlink.examples.fault_detection.rules import (
    INITIAL_MEMORY,
    LightCommand,
    RobotMemory,
    RuleConfig,
    Sensor,
    event_failure,
    step,
    window_complete,
    window_verdict,
)
from fleetlink.examples.fault_detection.settings import FaultDetectionSettings, check_copartitioned

try:
    from quixstreams import Application, State
    from quixstreams.dataframe.windows.aggregations import Count, Max, Sum
    from quixstreams.models import Row, SchemaRegistryClientConfig
    from quixstreams.models.serializers.avro import AvroDeserializer, AvroSerializer
    from quixstreams.models.serializers.exceptions import SerializationError
except ModuleNotFoundError as exc:  # the demo's stream app is an extra, not part of an edge install
    raise missing_extra(exc, "demo") from None

__all__ = ["COMMAND_ID_HEADER", "LIGHTRING_TYPE", "build_app", "lightring_schema", "run"]

logger = logging.getLogger(__name__)

LIGHTRING_TYPE = "irobot_create_msgs/msg/LightringLeds"
COMMAND_ID_HEADER = "fleetlink-command-id"
MEMORY_KEY = "robot"
STOP_CHECK_S = 0.1

CommandCallback = Callable[[LightCommand], None]


class _Application(Application):
    """An Application that can also run in a thread that is not the main one.

    ``Application.run()`` installs SIGINT/SIGTERM handlers, which Python only allows in the
    main thread; elsewhere, stopping is the caller's job (``run(settings, stop_event)``).
    """

    def _setup_signal_handlers(self) -> None:
        if threading.current_thread() is threading.main_thread():
            super()._setup_signal_handlers()  # type: ignore[no-untyped-call]


class _RateLimitedLog:
    """Log the first skipped record of each kind in full, then one line per ``every`` more."""

    def __init__(self, every: int = 100) -> None:
        self._every = every
        self._counts: dict[str, int] = {}

    def __call__(self, kind: str, message: str) -> None:
        count = self._counts.get(kind, 0) + 1
        self._counts[kind] = count
        if count == 1:
            logger.warning("%s (further ones counted, logged every %d)", message, self._every)
        elif count % self._every == 0:
            logger.warning("%d records skipped so far of kind=%s; latest: %s", count, kind, message)


def lightring_schema(settings: FaultDetectionSettings) -> dict[str, Any]:
    """The Avro schema of LightringLeds, from ``msg_paths`` or else the packages fleetlink ships."""
    from fleetlink.schemas.avro_schema import avro_schema
    from fleetlink.schemas.errors import SchemaError
    from fleetlink.schemas.typestore import load_typestore

    paths = settings.msg_paths  # the bundled irobot_create_msgs unless a copy is given
    try:
        ts = load_typestore(settings.distro, paths)
        return avro_schema(ts, LIGHTRING_TYPE, settings.distro)
    except SchemaError as exc:
        raise SettingsError(f"cannot derive the {LIGHTRING_TYPE} schema from {paths}: {exc}") from exc


def _classifier(sensor: Sensor, config: RuleConfig) -> Callable[[Any, Any, int, Any], dict[str, Any]]:
    def classify(record: Any, _key: Any, timestamp_ms: int, _headers: Any) -> dict[str, Any]:
        return {"sensor": sensor.value, "failure": event_failure(sensor, record, config), "ts": timestamp_ms}

    return classify


def _decider(
    min_events: int, on_command: CommandCallback | None
) -> Callable[[dict[str, Any], Any, int, Any, State[str, Any]], LightCommand | None]:
    def decide(
        window: dict[str, Any], key: Any, _ts: int, _headers: Any, state: State[str, Any]
    ) -> LightCommand | None:
        if not window_complete(window["end"], window["newest"]):
            return None
        stored = state.get(MEMORY_KEY)
        memory = INITIAL_MEMORY if stored is None else RobotMemory.from_json(stored)
        verdict = window_verdict(window["events"], window["failures"], min_events)
        transition = step(str(key), memory, verdict, window["end"])
        if transition.memory != memory:
            state.set(MEMORY_KEY, transition.memory.to_json())
        command = transition.command
        if command is not None:
            logger.info(
                "robot=%s state=%s->%s window_end_ms=%d events=%d failures=%d command_id=%s",
                command.robot,
                memory.state,
                command.state,
                command.stamp_ms,
                window["events"],
                window["failures"],
                command.command_id,
            )
            if on_command is not None:
                on_command(command)
        return command

    return decide


def build_app(settings: FaultDetectionSettings, on_command: CommandCallback | None = None) -> Application:
    """The configured (not yet running) Quix Streams application.

    ``on_command`` is called in the processing thread for every state change, before the
    command is produced; it must be quick and must not raise.
    """
    schema = lightring_schema(settings)
    bad_records = _RateLimitedLog()

    def on_consumer_error(exc: Exception, message: Any, _logger: logging.Logger) -> bool:
        if isinstance(exc, SerializationError) and message is not None:
            bad_records(
                "undecodable",
                f"skipping undecodable record topic={message.topic()} partition={message.partition()} "
                f"offset={message.offset()} key={message.key()!r} error={exc}",
            )
            return True
        return False

    def on_late(  # noqa: PLR0917 - the signature is Quix Streams' WindowOnLateCallback
        value: Any,
        key: Any,
        timestamp_ms: int,
        late_by_ms: int,
        start: int,
        end: int,
        store_name: str,
        topic: str,
        partition: int,
        offset: int,
    ) -> bool:
        bad_records(
            "late",
            f"late record not counted: robot={key} timestamp_ms={timestamp_ms} late_by_ms={late_by_ms} "
            f"window=({start}, {end}) store={store_name} topic={topic} partition={partition} "
            f"offset={offset} value={value!r:.80}",
        )
        return False  # logged here, rate-limited

    def on_processing_error(exc: Exception, row: Row | None, _logger: logging.Logger) -> bool:
        if isinstance(exc, BadRecordError):
            where = "" if row is None else f"topic={row.topic} partition={row.partition} offset={row.offset} "
            bad_records(
                f"bad-{exc.sensor}", f"skipping record {where}key={getattr(row, 'key', None)!r}: {exc}"
            )
            return True
        return False

    app = _Application(
        broker_address=settings.bootstrap,
        consumer_group=settings.group,
        auto_offset_reset=settings.offset_reset,
        state_dir=settings.state_dir,
        consumer_poll_timeout=settings.poll_timeout,
        commit_interval=settings.commit_interval,
        on_consumer_error=on_consumer_error,
        on_processing_error=on_processing_error,
        loglevel=None,
    )
    registry = SchemaRegistryClientConfig(url=settings.registry_url)
    deserializer = AvroDeserializer(schema_registry_client_config=registry)
    rules = settings.rule_config()
    topics = settings.topics
    sources = (
        (Sensor.IR_INTENSITY, topics.ir_intensity),
        (Sensor.HAZARD_DETECTION, topics.hazard_detection),
        (Sensor.KIDNAP_STATUS, topics.kidnap_status),
    )
    frames = [
        app.dataframe(app.topic(name, key_deserializer="str", value_deserializer=deserializer)).apply(
            _classifier(sensor, rules), metadata=True
        )
        for sensor, name in sources
    ]
    events = frames[0].concat(frames[1]).concat(frames[2])
    windows = (
        events.sliding_window(
            duration_ms=round(settings.window * 1000), grace_ms=round(settings.grace * 1000), on_late=on_late
        )
        .agg(events=Count(), failures=Sum("failure"), newest=Max("ts"))
        .current()
    )
    commands = windows.apply(_decider(settings.min_events, on_command), stateful=True, metadata=True)
    commands = commands.filter(lambda command: command is not None)
    commands = commands.set_headers(
        lambda command, _k, _t, _h: [(COMMAND_ID_HEADER, command.command_id.encode())]
    )
    commands = commands.set_timestamp(lambda command, _k, _t, _h: command.stamp_ms)
    out = app.topic(
        topics.commands,
        key_serializer="str",
        value_serializer=AvroSerializer(schema, schema_registry_client_config=registry),
    )
    commands.apply(lambda command: command.record()).to_topic(out)
    return app


def run(
    settings: FaultDetectionSettings,
    stop_event: threading.Event | None = None,
    on_command: CommandCallback | None = None,
) -> None:
    """Build and run the app until ``stop_event`` is set (or SIGINT/SIGTERM in the main thread).

    Safe to call from any thread. After ``stop_event`` is set the app finishes the record in
    hand, commits and closes within about one poll timeout plus the final commit.
    """
    app = build_app(settings, on_command)
    _check_sensor_topics(settings)
    if stop_event is None:
        app.run()
        return
    finished = threading.Event()
    watcher = threading.Thread(
        target=_stop_when_set, args=(app, stop_event, finished), name="fault-detection-stop", daemon=True
    )
    watcher.start()
    try:
        app.run()
    finally:
        finished.set()
        watcher.join()


def _check_sensor_topics(settings: FaultDetectionSettings) -> None:
    """Refuse to start on sensor topics with different partition counts (missing ones are created alike)."""
    from confluent_kafka import KafkaException
    from confluent_kafka.admin import AdminClient

    topics = settings.topics
    names = (topics.ir_intensity, topics.hazard_detection, topics.kidnap_status)
    try:
        metadata = AdminClient({"bootstrap.servers": settings.bootstrap}).list_topics(timeout=30)
    except KafkaException as exc:
        raise FaultDetectionError(f"cannot reach Kafka at {settings.bootstrap}: {exc}") from exc
    check_copartitioned(
        {
            name: len(metadata.topics[name].partitions)
            for name in names
            if name in metadata.topics and metadata.topics[name].error is None
        }
    )


def _stop_when_set(app: Application, stop_event: threading.Event, finished: threading.Event) -> None:
    # Application.run() clears a stop requested before it started, so keep asking until it ends.
    while not finished.is_set():
        if stop_event.wait(STOP_CHECK_S) and not finished.is_set():
            app.stop()
            finished.wait(STOP_CHECK_S)
