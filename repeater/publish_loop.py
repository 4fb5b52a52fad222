"""Publishing: one thread wakes when the schedule says a command is due (or when poked), and
publishes it under the repeater's lock, so nothing is published for a command whose lease (or
dead-man limit) has run out."""

from __future__ import annotations

import logging
import threading

import zenoh

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.repeater.errors import JournalError
from fleetlink.repeater.graph_events import SubscriberWatch
from fleetlink.repeater.schedule import Publish
from fleetlink.repeater.shared import Shared
from fleetlink.repeater.statuses import record
from fleetlink.roswire.errors import QosParseError, RoswireError

log = logging.getLogger(__name__)

MAX_WAIT_S = 0.5


class PublishLoop:
    """The thread that publishes what is due: restored commands, repeats, late joiners; it also ends
    expired commands and compacts the journal."""

    def __init__(self, shared: Shared, subscribers: SubscriberWatch) -> None:
        self._shared = shared
        self._subscribers = subscribers
        self._limiter = LogLimiter(log)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Start the ``repeater-schedule`` thread, which publishes what falls due until :meth:`stop`."""
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="repeater-schedule", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread and wait for it (at most 5 s)."""
        self._stop.set()
        self._shared.poke.set()
        if self._thread is not None:
            self._thread.join(5)
            self._thread = None

    def publish(self, items: list[Publish], now: float) -> None:
        """Publish (under the lock) what the schedule asked for; report first deliveries."""
        shared = self._shared
        publishers = shared.publishers
        if publishers is None:
            shared.initial += items
            return
        for item in items:
            cmd = item.command
            known = shared.cdr.get(cmd.ident)
            if known is None or not shared.schedule.is_active(cmd):
                continue
            env, cdr = known
            try:
                publishers.get(env.ros_topic, env.ros_type, env.qos).publish_cdr(cdr)
            except (RoswireError, QosParseError, zenoh.ZError) as exc:
                shared.stats.publish_errors += 1
                log.warning("publishing command %s on %s failed: %s", cmd.command_id, cmd.ros_topic, exc)
                continue
            shared.stats.publishes += 1
            shared.stats.by_topic[cmd.ros_topic] += 1
            if item.reason == "late-joiner":
                shared.stats.late_joiner_publishes += 1
            seen = self._subscribers.count(cmd.ros_topic) > 0
            record(shared, shared.schedule.published(cmd, now, seen=seen))

    def _run(self) -> None:
        shared = self._shared
        while not self._stop.is_set():
            shared.poke.clear()
            with shared.lock:
                now = shared.clock()
                items, shared.initial = shared.initial, []
                for topic in sorted(self._subscribers.take_joined()):
                    items += shared.schedule.subscriber_appeared(topic, now)
                due, changes = shared.schedule.tick(now)
                record(shared, changes)
                self.publish(items + due, now)
                if shared.publishers is not None:
                    shared.publishers.sweep(now)
                try:
                    shared.store.maybe_compact(now)
                except JournalError as exc:  # the journal keeps growing; everything else goes on
                    self._limiter.log(logging.ERROR, "compact", "repeater journal compaction failed: %s", exc)
                wake = shared.schedule.next_wakeup()
                timeout = MAX_WAIT_S if wake is None else min(max(wake - shared.clock(), 0.001), MAX_WAIT_S)
            shared.poke.wait(timeout)
