"""The uplink's command router: command topics (Kafka) -> the robots' sites (Zenoh).

One consumer in the group ``<kafka.client_id>.commands`` reads every mapping's ``from``
topic (so uplinks share the work by partition). Each record is handled on a worker thread:

1. decoded through the registry (undecodable -> command dead-letter topic);
2. planned: command id, lease from the record timestamp, robots and their sites
   (:mod:`uplink.commands.plan`); a record whose lease already ended -> ``expired`` status;
3. forwarded (:class:`~uplink.commands.forwarder.Forwarder`) until a repeater settles it or
   its lease ends (-> ``expired`` status).

Its offset is committed only once all that is done (dead letter or status records included
acknowledged by Kafka); records settle out of order, the committed position never passes one
that has not (:class:`~uplink.commands.offsets.OffsetTracker`). After a crash the unsettled
records come again with the same command id, and the repeaters apply each id once.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any

import zenoh
from confluent_kafka import Consumer, KafkaException, Message, TopicPartition

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.schemas.registry import SchemaRegistry
from fleetlink.uplink.calls.convert import CallTypes
from fleetlink.uplink.calls.mapping import ActionMapping, ServiceMapping
from fleetlink.uplink.calls.outcomes import OUTCOME_KEY, OutcomeIntake, OutcomeWriter
from fleetlink.uplink.calls.route import CallRoute, Role
from fleetlink.uplink.commands.decode import CommandDecoder, DecodedValue
from fleetlink.uplink.commands.directory import RobotDirectory
from fleetlink.uplink.commands.errors import RegistryUnreachableError, RoutingError, UndecodableValueError
from fleetlink.uplink.commands.forwarder import Forwarder
from fleetlink.uplink.commands.mapping import CommandMapping
from fleetlink.uplink.commands.offsets import OffsetTracker
from fleetlink.uplink.commands.plan import CommandRecord, Forward, command_id, lease_until_ms, plan
from fleetlink.uplink.commands.registrations import RegistrationsReader
from fleetlink.uplink.commands.signing import CommandSigner, load_signer
from fleetlink.uplink.commands.status_writer import STATUS_KEY, StatusIntake, StatusWriter
from fleetlink.uplink.config import UplinkConfig
from fleetlink.uplink.consumer_poll import poll_once
from fleetlink.uplink.dead_letter import dead_letter
from fleetlink.uplink.producer import KafkaSink
from fleetlink.wire.calls import Outcome
from fleetlink.wire.commands import StatusEvent

CallRole = tuple[Role, ServiceMapping | ActionMapping]

log = logging.getLogger(__name__)


@dataclass
class RouterStats:
    """The command router's counters, updated by its worker threads through :meth:`add`."""

    records: int = 0
    forwards: int = 0
    dead_lettered: int = 0
    expired_before_forward: int = 0
    expired_unacknowledged: int = 0
    settled: int = 0
    results: Counter[str] = field(default_factory=Counter)
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def add(self, **counts: int) -> None:
        """Add ``counts`` (counter name -> amount) under the lock."""
        with self.lock:
            for name, value in counts.items():
                setattr(self, name, getattr(self, name) + value)


class CommandRouter:
    """Reads the command, request and goal topics, sends each record to its robots' sites, and commits its
    offset once it has settled."""

    def __init__(
        self,
        config: UplinkConfig,
        *,
        session: zenoh.Session,
        sink: KafkaSink,
        registry: SchemaRegistry,
        group_id: str | None = None,
        clock: Callable[[], float] = time.time,
        query_timeout: float = 5.0,
        workers: int = 32,
        max_in_flight: int = 256,
        directory: RobotDirectory | None = None,
        signer: CommandSigner | None = None,
        call_types: CallTypes | None = None,
    ) -> None:
        """``call_types`` (the ROS types of ``services`` and ``actions``) is needed when the config
        has service or action mappings (docs/services.md): they share this router's consumer."""
        self.config = config
        self.group_id = group_id or f"{config.kafka.client_id}.commands"
        self._session = session
        self._sink = sink
        self._clock = clock
        self._workers = workers
        self._max_in_flight = max_in_flight
        self._lock = threading.Lock()
        self._mappings: dict[str, list[CommandMapping]] = {}
        self._subscribed: tuple[str, ...] = ()
        self._calls: dict[str, list[CallRole]] = {}
        self.set_mappings(config.commands)
        self.set_call_mappings(config.services, config.actions)
        self.stats = RouterStats()
        self._own_directory = directory is None
        self.directory = directory if directory is not None else RobotDirectory()
        """Where each robot is; the uplink's (fed by its reader) or, when none is given, this router's own."""
        self.decoder = CommandDecoder(registry)
        self.status_writer = StatusWriter(sink, registry, config.topics.command_status)
        self.intake = StatusIntake(self.status_writer, owner_of=self.directory.owner)
        self._stop = threading.Event()
        if signer is None:
            signer = load_signer(config)
        self.forwarder = Forwarder(
            session, query_timeout=query_timeout, clock=clock, stop=self._stop, signer=signer
        )
        self._tracker = OffsetTracker()
        self.assigned = threading.Event()
        """Set once the consumer group gave this router its first partitions."""
        self._limiter = LogLimiter(log)
        self.outcomes: OutcomeWriter | None = None
        self.outcome_intake: OutcomeIntake | None = None
        self.calls: CallRoute | None = None
        if config.services or config.actions:
            if call_types is None:
                raise ValueError("service and action mappings need the ROS types (call_types)")
            self.outcomes = OutcomeWriter(sink, registry, call_types, config.services, config.actions)
            self.outcome_intake = OutcomeIntake(self.outcomes, owner_of=self.directory.owner)
            self.calls = CallRoute(
                call_types,
                self.forwarder,
                self.outcomes,
                site_of=self.directory.site_of,
                clock=clock,
                stopping=self._stop.is_set,
            )
        self._outcome_queryable: Any = None
        self._reader: RegistrationsReader | None = None
        self._queryable: Any = None
        self._pool: ThreadPoolExecutor | None = None
        self._consumer: Consumer | None = None
        self._thread: threading.Thread | None = None

    # -- lifecycle ------------------------------------------------------------------------

    def start(self, *, registrations_catch_up_s: float = 10.0) -> CommandRouter:
        """Declare the status (and outcome) queryables, start the registrations reader when the directory
        is the router's own, then the workers and the consumer thread; returns self."""
        cfg = self.config
        self._stop.clear()
        self._queryable = self._session.declare_queryable(STATUS_KEY, self.intake.on_query)
        if self.outcome_intake is not None:
            self._outcome_queryable = self._session.declare_queryable(
                OUTCOME_KEY, self.outcome_intake.on_query
            )
        if self._own_directory:
            self._reader = RegistrationsReader(
                cfg.kafka, cfg.topics.registrations, self.decoder, self.directory
            ).start(registrations_catch_up_s)
        self._pool = ThreadPoolExecutor(max_workers=self._workers, thread_name_prefix="uplink-command")
        self._consumer = Consumer(dict(cfg.kafka.consumer_config(self.group_id)))
        self._thread = threading.Thread(target=self._run, name="uplink-commands", daemon=True)
        self._thread.start()
        log.info("command router: group %s, topics %s", self.group_id, sorted(self._mappings))
        return self

    def stop(self) -> None:
        """Stop the consumer thread and the workers, commit what has settled, close the consumer and the
        registrations reader, and undeclare the queryables."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(15)
            self._thread = None
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        if self._consumer is not None:
            self._commit(self._consumer)
            self._consumer.close()
            self._consumer = None
        if self._reader is not None:
            self._reader.stop()
            self._reader = None
        if self._queryable is not None:
            self._queryable.undeclare()
            self._queryable = None
        if self._outcome_queryable is not None:
            self._outcome_queryable.undeclare()
            self._outcome_queryable = None

    def __enter__(self) -> CommandRouter:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def set_mappings(self, mappings: Sequence[CommandMapping]) -> None:
        """Replace the command mappings at runtime (the consumer re-subscribes)."""
        by_topic: dict[str, list[CommandMapping]] = {}
        for mapping in mappings:
            by_topic.setdefault(mapping.from_, []).append(mapping)
        with self._lock:
            self._mappings = by_topic

    def set_call_mappings(self, services: Sequence[ServiceMapping], actions: Sequence[ActionMapping]) -> None:
        """Replace the topics the service and action mappings read (requests, goals, cancels)."""
        by_topic: dict[str, list[CallRole]] = {}
        for service in services:
            by_topic.setdefault(service.from_, []).append(("service", service))
        for action in actions:
            by_topic.setdefault(action.from_, []).append(("goal", action))
            if action.cancel_from is not None:
                by_topic.setdefault(action.cancel_from, []).append(("cancel", action))
        with self._lock:
            self._calls = by_topic

    def in_flight(self) -> int:
        """How many records were read and have not settled yet."""
        return self._tracker.in_flight()

    def lag_s(self) -> float:
        """Age of the oldest command read and not yet settled (``fleetlink_command_lag_seconds``)."""
        return self._tracker.oldest_age_s()

    # -- consumer thread ------------------------------------------------------------------

    def _run(self) -> None:
        consumer = self._consumer
        if consumer is None:
            return
        last_commit = 0.0
        while not self._stop.is_set():
            with self._lock:
                topics = tuple(sorted(set(self._mappings) | set(self._calls)))
            if topics != self._subscribed:
                self._subscribe(consumer, topics)
            if not topics or self._tracker.in_flight() >= self._max_in_flight:
                self._stop.wait(0.05)
            else:
                msg = poll_once(consumer, 0.1, self._stop, self._failed)
                if msg is not None:
                    self._dispatch(msg)
            if time.monotonic() - last_commit >= 0.2:
                self._commit(consumer)
                last_commit = time.monotonic()

    def _failed(self, exc: KafkaException) -> None:
        self._limiter.log(logging.WARNING, "poll", "command consumer: %s", exc)

    def _subscribe(self, consumer: Consumer, topics: tuple[str, ...]) -> None:
        if topics:
            consumer.subscribe(list(topics), on_assign=self._on_assign, on_revoke=self._on_revoke)
        else:
            consumer.unsubscribe()
        self._subscribed = topics

    def _on_assign(self, _consumer: Consumer, partitions: list[TopicPartition]) -> None:
        log.info("command partitions assigned: %s", [f"{tp.topic}[{tp.partition}]" for tp in partitions])
        self.assigned.set()

    def _on_revoke(self, consumer: Consumer, partitions: list[TopicPartition]) -> None:
        self._commit(consumer)
        self._tracker.forget([(tp.topic, tp.partition) for tp in partitions])

    def _commit(self, consumer: Consumer) -> None:
        positions = self._tracker.committable()
        if not positions:
            return
        try:
            consumer.commit(
                offsets=[TopicPartition(t, p, o) for (t, p), o in positions.items()], asynchronous=False
            )
        except KafkaException as exc:
            self._limiter.log(logging.WARNING, "commit", "committing command offsets failed: %s", exc)
            return
        self._tracker.committed(positions)

    def _dispatch(self, msg: Message) -> None:
        err = msg.error()
        if err is not None:
            self._limiter.log(logging.WARNING, f"consume:{err.code()}", "command consumer: %s", err.str())
            return
        topic, partition, offset = msg.topic(), msg.partition(), msg.offset()
        if topic is None or partition is None or offset is None:
            return
        ts_type, ts = msg.timestamp()
        record = CommandRecord(
            topic,
            partition,
            offset,
            msg.key(),
            msg.value(),
            tuple((k, v or b"") for k, v in (msg.headers() or [])),
            ts if ts_type else -1,
        )
        with self._lock:
            mappings = list(self._mappings.get(topic, ()))
            calls = list(self._calls.get(topic, ()))
        self.stats.add(records=1)
        self._tracker.begin((topic, partition), offset)
        pool = self._pool
        if pool is not None:
            pool.submit(self._process, record, mappings, calls)

    # -- one record (worker thread) -------------------------------------------------------

    def _process(
        self, record: CommandRecord, mappings: list[CommandMapping], calls: list[CallRole] | None = None
    ) -> None:
        try:
            if self._handle(record, mappings, calls or []):
                self._tracker.done((record.topic, record.partition), record.offset)
        except Exception:  # a bug must not leave the offset silently committed: log, keep it pending
            log.exception("command %s: unexpected failure; the record stays uncommitted", record.source)

    def _handle(self, record: CommandRecord, mappings: list[CommandMapping], calls: list[CallRole]) -> bool:
        """True when the record is settled (its offset may be committed)."""
        decoded = self._decode(record, mappings)
        if decoded is None:
            return not self._stop.is_set()
        if isinstance(decoded, str):
            return self._dead_letter(record, "command-decode", decoded)
        settled = all(self._route(record, mapping, decoded) for mapping in mappings)
        for role, call in calls:
            settled = self._route_call(record, role, call, decoded) and settled
        return settled

    def _route_call(
        self,
        record: CommandRecord,
        role: Role,
        mapping: ServiceMapping | ActionMapping,
        decoded: DecodedValue,
    ) -> bool:
        route = self.calls
        if route is None:
            return True
        try:
            forward = route.plan(role, record, mapping, decoded)
        except UndecodableValueError as exc:
            return self._dead_letter(record, "call-decode", f"mapping {mapping.name}: {exc.reason}")
        except RoutingError as exc:
            return self._dead_letter(record, "call-route", f"mapping {mapping.name}: {exc}")
        self.stats.add(forwards=1)
        settled, outcome = route.send(forward)
        if outcome is None:
            if settled:
                self.stats.add(settled=1)
            return settled
        return self._outcomes([outcome])

    def _outcomes(self, outcomes: list[Outcome]) -> bool:
        writer = self.outcomes
        delay = 0.2
        while writer is not None:
            problem = writer.write_and_wait(outcomes)
            if problem is None:
                return True
            self._limiter.log(
                logging.WARNING, "outcome", "writing call outcomes failed: %s; retrying", problem
            )
            if self._stop.wait(delay):
                return False
            delay = min(delay * 2, 5.0)
        return True

    def _decode(self, record: CommandRecord, mappings: list[CommandMapping]) -> DecodedValue | str | None:
        """The decoded value, the reason it is undecodable, or None (gave up: expired or stopping)."""
        delay = 0.2
        while True:
            try:
                return self.decoder.decode(record.value)
            except UndecodableValueError as exc:
                return exc.reason
            except RegistryUnreachableError as exc:
                now_ms = int(self._clock() * 1000)
                if mappings and all(now_ms >= lease_until_ms(record, m, now_ms) for m in mappings):
                    self._limiter.log(
                        logging.WARNING,
                        "registry-expired",
                        "command %s expired while the registry was unreachable: %s",
                        record.source,
                        exc,
                    )
                    self.stats.add(expired_before_forward=1)
                    return None
                self._limiter.log(logging.WARNING, "registry", "command %s: %s; retrying", record.source, exc)
                if self._stop.wait(delay):
                    return None
                delay = min(delay * 2, 2.0)

    def _route(self, record: CommandRecord, mapping: CommandMapping, decoded: DecodedValue) -> bool:
        now_ms = int(self._clock() * 1000)
        try:
            forwards = plan(
                record,
                mapping,
                decoded,
                now_ms=now_ms,
                site_of=self.directory.site_of,
                registered=self.directory.registered(),
            )
        except RoutingError as exc:
            return self._dead_letter(record, "command-route", f"mapping {mapping.name}: {exc}")
        if not forwards:
            return True  # a broadcast with no registered robot
        until = forwards[0].envelope.lease_until_ms
        if now_ms >= until:
            self.stats.add(expired_before_forward=len(forwards))
            detail = f"lease ended {(now_ms - until) / 1000:.1f} s before the uplink could forward it"
            return self._statuses([self._expired(f, record, now_ms, detail) for f in forwards])
        statuses: list[StatusEvent] = []
        for forward in forwards:
            self.stats.add(forwards=1)
            result = self.forwarder.send(forward)
            for reply in result.replies:
                with self.stats.lock:
                    self.stats.results[reply.result] += 1
            if result.settled:
                self.stats.add(settled=1)
                continue
            if self._stop.is_set():
                return False  # not settled: it comes again after the restart
            self.stats.add(expired_unacknowledged=1)
            statuses.append(self._expired(forward, record, int(self._clock() * 1000), result.detail))
        return self._statuses(statuses)

    @staticmethod
    def _expired(forward: Forward, record: CommandRecord, now_ms: int, detail: str) -> StatusEvent:
        env = forward.envelope
        return StatusEvent(command_id(record), env.robot, env.ros_topic, "expired", now_ms, "", detail)

    def _statuses(self, events: list[StatusEvent]) -> bool:
        delay = 0.2
        while events:
            problem = self.status_writer.write_and_wait(events)
            if problem is None:
                return True
            self._limiter.log(
                logging.WARNING, "status", "writing command status failed: %s; retrying", problem
            )
            if self._stop.wait(delay):
                return False
            delay = min(delay * 2, 5.0)
        return True

    def _dead_letter(self, record: CommandRecord, stage: str, reason: str) -> bool:
        cfg = self.config
        dl = dead_letter(
            dlq_topic=cfg.topics.command_dead_letter,
            stage=stage,
            reason=reason,
            intended_topic=record.topic,
            key=record.key,
            raw=record.value or b"",
            headers=record.headers,
            timestamp_ms=max(record.timestamp_ms, 0),
            max_value_bytes=max(1_000, cfg.kafka.message_max_bytes - 65_536),
        )
        self._limiter.log(
            logging.WARNING, f"dlq:{stage}", "command %s dead-lettered: %s", record.source, reason
        )
        delay = 0.2
        while True:
            done = threading.Event()
            errors: list[str] = []

            def delivered(report: Any, done: threading.Event = done, errors: list[str] = errors) -> None:
                if report.error is not None:
                    errors.append(str(report.error))
                done.set()

            try:
                self._sink.produce(
                    dl.topic,
                    dl.key,
                    dl.value,
                    headers=dl.headers,
                    timestamp_ms=dl.timestamp_ms,
                    on_delivery=delivered,
                )
                done.wait(cfg.kafka.delivery_timeout + 5)
            except Exception as exc:  # noqa: BLE001 - retried below
                errors.append(str(exc))
            if done.is_set() and not errors:
                self.stats.add(dead_lettered=1)
                return True
            self._limiter.log(
                logging.WARNING,
                "dlq-write",
                "dead-letter write failed: %s; retrying",
                errors[0] if errors else "timeout",
            )
            if self._stop.wait(delay):
                return False
            delay = min(delay * 2, 5.0)


__all__ = ["CommandRouter", "RouterStats"]
