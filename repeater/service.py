"""The repeater process: commands from the uplink, repeated near the robots under a lease.

* a queryable on ``fleetlink/<site>/command/**`` takes command envelopes, converts each Avro
  value to CDR, publishes it at once, journals the command (fsynced before the answer) and
  answers what it did (``applied``, ``duplicate``, ``expired``, ``superseded``, ``rejected``,
  ``need-schema``);
* the :class:`~repeater.schedule.Schedule` decides what to publish when; one rmw_zenoh
  publisher per ROS topic publishes it;
* a :class:`~roswire.discovery.GraphWatcher` sees subscriber (``MS``) tokens appear: a late
  joiner gets the active command at once, and a publish with a subscriber present is a
  delivery;
* a :class:`~repeater.status_link.StatusLink` sends status events to the uplink and is the
  pulse the dead-man watches.

All publishing happens under one lock, after the schedule said so: nothing is ever published
for a command whose lease (or dead-man limit) has run out.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any

import zenoh

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.common.zenoh_options import ZenohOptions
from fleetlink.repeater.config import RepeaterConfig
from fleetlink.repeater.converter import Converter
from fleetlink.repeater.errors import ConversionError, JournalError, RepeaterConfigError
from fleetlink.repeater.publishers import Publishers
from fleetlink.repeater.schedule import Change, Command, Offer, Publish, Schedule
from fleetlink.repeater.state import CommandStore
from fleetlink.repeater.status_link import StatusLink
from fleetlink.roswire.discovery import GraphWatcher
from fleetlink.roswire.errors import QosParseError, RoswireError
from fleetlink.roswire.graph import EventKind, GraphEvent
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.session import open_session, ros_session_config
from fleetlink.roswire.tokens import EndpointInfo, EntityKind
from fleetlink.schemas.errors import SchemaError
from fleetlink.schemas.typestore import load_typestore
from fleetlink.wire.commands import (
    CommandEnvelope,
    CommandReply,
    Result,
    StatusEvent,
    decode_envelope,
    encode_reply,
)
from fleetlink.wire.errors import EnvelopeError
from fleetlink.wire.keys import command_key, site_prefix

log = logging.getLogger(__name__)

MAX_WAIT_S = 0.5
_FINAL = frozenset({"superseded", "expired", "rejected"})
_RESULT: dict[Offer, Result] = {
    Offer.APPLIED: "applied",
    Offer.DUPLICATE: "duplicate",
    Offer.EXPIRED: "expired",
    Offer.SUPERSEDED: "superseded",
}


@dataclass
class RepeaterStats:
    applied: int = 0
    duplicates: int = 0
    expired_on_arrival: int = 0
    superseded_on_arrival: int = 0
    rejected: int = 0
    need_schema: int = 0
    malformed: int = 0
    publishes: int = 0
    late_joiner_publishes: int = 0
    publish_errors: int = 0
    by_topic: Counter[str] = field(default_factory=Counter)
    """Publishes per ROS topic."""


def to_command(env: CommandEnvelope) -> Command:
    return Command(
        env.command_id,
        env.robot,
        env.ros_topic,
        env.issued_at_ms / 1000,
        env.lease_until_ms / 1000,
        env.period_ms / 1000,
        env.order,
    )


class Repeater:
    def __init__(
        self,
        config: RepeaterConfig,
        zenoh_options: ZenohOptions | None = None,
        *,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.config = config
        self.site = config.repeater.site
        self.id = config.repeater.id
        self._options = zenoh_options or config.zenoh.options()
        self._clock = clock
        self.stats = RepeaterStats()
        self._limiter = LogLimiter(log)
        self.schedule = Schedule(dead_man=config.repeater.dead_man)
        self.store = CommandStore(config.repeater.state_dir)
        self._lock = threading.RLock()
        self._poke = threading.Event()  # wakes the schedule thread (set without taking the lock)
        self._stop = threading.Event()
        self._cdr: dict[tuple[str, str], tuple[CommandEnvelope, bytes]] = {}
        self._initial: list[Publish] = []
        self._graph_lock = threading.Lock()
        self._subscribers: Counter[str] = Counter()
        self._joined: set[str] = set()
        self._converter: Converter | None = None
        self._session: zenoh.Session | None = None
        self._node: RosNode | None = None
        self._watcher: GraphWatcher | None = None
        self._publishers: Publishers | None = None
        self._queryable: Any = None
        self._link: StatusLink | None = None
        self._thread: threading.Thread | None = None

    # -- lifecycle ------------------------------------------------------------------------

    def start(self) -> Repeater:
        ros = self.config.ros
        try:
            typestore = load_typestore(ros.distro, ros.message_paths)
        except SchemaError as exc:
            raise RepeaterConfigError(f"ros.message_paths: cannot load message types: {exc}") from None
        self._converter = Converter(typestore, ros.distro)
        self.store.open()
        with self._lock:
            self._restore()
        self._session = open_session(ros_session_config(self._options))
        self._node = RosNode(
            "fleetlink_repeater",
            "/",
            domain_id=ros.domain_id,
            session=self._session,
            typestore=typestore,
            distro=ros.distro,
        ).start()
        self._publishers = Publishers(self._node)
        self._watcher = GraphWatcher(self._session, ros.domain_id, listeners=(self._on_graph,)).start()
        cfg = self.config.repeater
        self._link = StatusLink(
            self._session,
            self.site,
            self.id,
            heartbeat=cfg.heartbeat,
            timeout=cfg.status_timeout,
            on_link=self._on_link,
            on_acked=self._on_acked,
        )
        for number, event in sorted(self.store.pending.items()):
            self._link.submit(number, event)
        self._link.start()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="repeater-schedule", daemon=True)
        self._thread.start()
        key = f"{site_prefix(self.site)}/command/**"
        self._queryable = self._session.declare_queryable(key, self._on_query)
        log.info("repeater %s serving %s (%d commands resumed)", self.id, key, len(self.schedule.active()))
        return self

    def stop(self) -> None:
        if self._queryable is not None:
            self._queryable.undeclare()
            self._queryable = None
        self._stop.set()
        self._poke.set()
        if self._thread is not None:
            self._thread.join(5)
            self._thread = None
        if self._link is not None:
            self._link.stop()
            self._link = None
        if self._watcher is not None:
            self._watcher.stop()
            self._watcher = None
        with self._lock:
            if self._publishers is not None:
                self._publishers.stop_all()
                self._publishers = None
        if self._node is not None:
            self._node.stop()
            self._node = None
        if self._session is not None:
            self._session.close()
            self._session = None
        self.store.close()

    def __enter__(self) -> Repeater:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    # -- commands in ----------------------------------------------------------------------

    def _on_query(self, query: zenoh.Query) -> None:
        try:
            payload = query.payload
            if payload is None:
                raise EnvelopeError("command envelope", "the query carries no payload")
            env = decode_envelope(payload.to_bytes())
        except EnvelopeError as exc:
            self.stats.malformed += 1
            log.warning("refused a malformed command on %s: %s", query.key_expr, exc)
            query.reply_err(str(exc).encode())
            query.drop()
            return
        try:
            with self._lock:
                self.schedule.link_up()
                reply = self.accept(env)
            self._poke.set()
            self.store.sync()  # durable before the uplink may commit (outside the lock: fsyncs overlap)
        except JournalError as exc:
            log.error("cannot make command %s durable: %s", env.command_id, exc)
            query.reply_err(f"repeater state not durable: {exc.reason}".encode())
            query.drop()
            return
        # reply on this site's own key (a query for every site carries a wildcard; routers'
        # ACLs let a site answer only under fleetlink/<site>/**)
        query.reply(command_key(self.site, env.robot, env.mapping), encode_reply(reply))
        query.drop()

    def accept(self, env: CommandEnvelope) -> CommandReply:
        """Apply one command envelope (call under the lock); publishes at once when applied."""
        now = self._clock()
        command = to_command(env)

        def reply(result: Result, detail: str = "") -> CommandReply:
            return CommandReply(env.command_id, env.robot, result, detail, self.site, self.id)

        if command.ident in self.schedule.seen():
            self.stats.duplicates += 1
            return reply("duplicate", "command id already applied")
        converter = self._converter
        if converter is None:
            raise RepeaterConfigError("repeater not started")
        schema = env.schema or self.store.schemas.get(env.schema_fp)
        if now < command.lease_until:
            try:
                own = converter.is_own_schema(env)
            except ConversionError as exc:
                problem = exc.reason
            else:
                if schema is None and not own:
                    self.stats.need_schema += 1
                    return reply("need-schema", f"writer schema {env.schema_fp.hex()} unknown here")
                problem = self._check(env, schema)
            if problem:
                self.stats.rejected += 1
                self.schedule.remember(command)
                self.store.command(env, now, ended=True)
                self._record([Change(command, "rejected", now, problem)])
                return reply("rejected", problem)
        outcome = self.schedule.offer(command, now)
        if outcome.offer is Offer.DUPLICATE:
            self.stats.duplicates += 1
            return reply("duplicate", outcome.detail)
        self.store.command(
            env if schema is None else env.with_schema(schema), now, ended=outcome.offer is not Offer.APPLIED
        )
        if outcome.offer is Offer.APPLIED:
            self.stats.applied += 1
        elif outcome.offer is Offer.EXPIRED:
            self.stats.expired_on_arrival += 1
        else:
            self.stats.superseded_on_arrival += 1
        self._record(outcome.changes)
        self._publish(outcome.publish, now)
        return reply(_RESULT[outcome.offer], outcome.detail)

    def _check(self, env: CommandEnvelope, schema: str | None) -> str:
        """Convert the command now (kept for its repeats); the reason it cannot be, or ''."""
        if self._converter is None:
            return "repeater not started"
        ident = (env.command_id, env.robot)
        current = {a.slot for a in self.schedule.active()}
        if (env.robot, env.ros_topic) not in current and len(current) >= self.config.repeater.max_active:
            return f"too many active commands (max_active={self.config.repeater.max_active})"
        try:
            cdr = self._converter.to_cdr(env, schema)
        except ConversionError as exc:
            return exc.reason
        self._cdr[ident] = (env, cdr)
        return ""

    def _restore(self) -> None:
        """Resume the commands of the journal whose lease holds; report the others expired."""
        now = self._clock()
        for ident, stored in list(self.store.commands.items()):
            env, command = stored.envelope, to_command(stored.envelope)
            if stored.ended:
                self.schedule.remember(command)
                continue
            problem = self._check(env, self.store.schemas.get(env.schema_fp))
            if problem:
                self.schedule.remember(command)
                self._record([Change(command, "rejected", now, f"after restart: {problem}")])
                continue
            outcome = self.schedule.offer(
                command, now, delivered=stored.delivered, received_at=stored.received_at
            )
            changes = outcome.changes
            if outcome.offer is Offer.EXPIRED:
                changes = [Change(command, "expired", now, "lease ended while the repeater was down")]
            self._record(changes)
            self._initial += outcome.publish
            log.debug("restored command %s: %s", ident, outcome.offer.value)
        self.store.maybe_compact(now, force=True)

    # -- statuses -------------------------------------------------------------------------

    def _record(self, changes: list[Change]) -> None:
        for change in changes:
            cmd = change.command
            ident = cmd.ident
            event = StatusEvent(
                cmd.command_id,
                cmd.robot,
                cmd.ros_topic,
                change.status,
                int(change.at * 1000),
                self.site,
                change.detail,
            )
            if change.status in _FINAL:
                self.store.mark(ident, "end")
                self._cdr.pop(ident, None)
                if self._publishers is not None and cmd.ros_topic not in self.schedule.topics():
                    self._publishers.release(cmd.ros_topic, change.at)
            elif change.status == "delivered":
                self.store.mark(ident, "delivered")
            number = self.store.status(event)
            if self._link is not None:
                self._link.submit(number, event)
            log.info(
                "command %s robot=%s topic=%s: %s (%s)",
                cmd.command_id,
                cmd.robot,
                cmd.ros_topic,
                change.status,
                change.detail,
            )

    def _on_acked(self, numbers: list[int]) -> None:
        with self._lock:
            self.store.acked(numbers)

    def _on_link(self, up: bool) -> None:
        with self._lock:
            if up:
                self.schedule.link_up()
            else:
                self.schedule.link_down(self._clock())
        self._poke.set()

    # -- publishing -----------------------------------------------------------------------

    def _on_graph(self, event: GraphEvent) -> None:
        # runs on a zenoh thread under the watcher's lock: never take the repeater's lock here
        entity = event.entity
        if not isinstance(entity, EndpointInfo) or entity.kind is not EntityKind.SUBSCRIPTION:
            return
        with self._graph_lock:
            if event.kind is EventKind.APPEARED:
                self._subscribers[entity.topic] += 1
                self._joined.add(entity.topic)
            else:
                self._subscribers[entity.topic] -= 1
                if self._subscribers[entity.topic] <= 0:
                    del self._subscribers[entity.topic]
        self._poke.set()

    def _publish(self, items: list[Publish], now: float) -> None:
        """Publish (under the lock) what the schedule asked for; report first deliveries."""
        publishers = self._publishers
        if publishers is None:
            self._initial += items
            return
        for item in items:
            cmd = item.command
            known = self._cdr.get(cmd.ident)
            if known is None or not self.schedule.is_active(cmd):
                continue
            env, cdr = known
            try:
                publishers.get(env.ros_topic, env.ros_type, env.qos).publish_cdr(cdr)
            except (RoswireError, QosParseError, zenoh.ZError) as exc:
                self.stats.publish_errors += 1
                log.warning("publishing command %s on %s failed: %s", cmd.command_id, cmd.ros_topic, exc)
                continue
            self.stats.publishes += 1
            self.stats.by_topic[cmd.ros_topic] += 1
            if item.reason == "late-joiner":
                self.stats.late_joiner_publishes += 1
            with self._graph_lock:
                seen = self._subscribers.get(cmd.ros_topic, 0) > 0
            self._record(self.schedule.published(cmd, now, seen=seen))

    def _run(self) -> None:
        while not self._stop.is_set():
            self._poke.clear()
            with self._lock:
                now = self._clock()
                items, self._initial = self._initial, []
                with self._graph_lock:
                    joined, self._joined = self._joined, set()
                for topic in sorted(joined):
                    items += self.schedule.subscriber_appeared(topic, now)
                due, changes = self.schedule.tick(now)
                self._record(changes)
                self._publish(items + due, now)
                if self._publishers is not None:
                    self._publishers.sweep(now)
                try:
                    self.store.maybe_compact(now)
                except JournalError as exc:  # the journal keeps growing; everything else goes on
                    self._limiter.log(logging.ERROR, "compact", "repeater journal compaction failed: %s", exc)
                wake = self.schedule.next_wakeup()
                timeout = MAX_WAIT_S if wake is None else min(max(wake - self._clock(), 0.001), MAX_WAIT_S)
            self._poke.wait(timeout)

    # -- views ----------------------------------------------------------------------------

    def subscribers(self, topic: str) -> int:
        with self._graph_lock:
            return self._subscribers.get(topic, 0)

    def pending_statuses(self) -> int:
        return self._link.pending() if self._link is not None else 0
