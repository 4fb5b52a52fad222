"""The repeater process: commands from the uplink, repeated near the robots under a lease.

It puts together four jobs, each in its own module, around the state they share
(:mod:`~repeater.shared`, one lock):

* :mod:`~repeater.intake`: a queryable on ``fleetlink/<site>/command/**`` takes command
  envelopes, converts each Avro value to CDR, publishes it at once, journals the command
  (fsynced before the answer) and answers what it did;
* :mod:`~repeater.restore`: at start, the journal's commands whose lease holds are resumed;
* :mod:`~repeater.graph_events`: a :class:`~roswire.discovery.GraphWatcher` sees subscriber
  (``MS``) tokens appear: a late joiner gets the active command at once, and a publish with a
  subscriber present is a delivery;
* :mod:`~repeater.publish_loop`: the :class:`~repeater.schedule.Schedule` decides what to
  publish when; one rmw_zenoh publisher per ROS topic publishes it.

A :class:`~repeater.status_link.StatusLink` sends status events (:mod:`~repeater.statuses`) to
the uplink and is the pulse the dead-man watches.

Service calls and action goals (docs/services.md) come on ``fleetlink/<site>/call/**``
(:mod:`~repeater.call_intake`), run as an rmw_zenoh client (:mod:`~repeater.call_runner`),
are journalled in ``calls.journal`` (:mod:`~repeater.call_store`) and their outcomes go to the
uplink on a second link, ``fleetlink/<site>/call-outcome/<id>``.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from types import TracebackType
from typing import Any

import zenoh
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from fleetlink.common.command_keys import load_public_key
from fleetlink.common.errors import FleetlinkError
from fleetlink.common.metrics import Health, NullMetrics, PrometheusMetrics, serve_metrics, split_listen
from fleetlink.common.metrics.server import HttpServer
from fleetlink.common.zenoh_options import ZenohOptions
from fleetlink.repeater.call_intake import CallIntake, final_outcome
from fleetlink.repeater.call_runner import CallRunner
from fleetlink.repeater.call_store import CallStore
from fleetlink.repeater.config import RepeaterConfig
from fleetlink.repeater.converter import Converter
from fleetlink.repeater.errors import RepeaterConfigError
from fleetlink.repeater.graph_events import SubscriberWatch
from fleetlink.repeater.intake import Intake
from fleetlink.repeater.publish_loop import PublishLoop
from fleetlink.repeater.publishers import Publishers
from fleetlink.repeater.restore import restore
from fleetlink.repeater.schedule import Schedule
from fleetlink.repeater.shared import RepeaterStats, Shared
from fleetlink.repeater.state import CommandStore
from fleetlink.repeater.status_link import StatusLink
from fleetlink.repeater.telemetry import RepeaterTelemetry
from fleetlink.roswire.discovery import GraphWatcher
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.session import open_session, ros_session_config
from fleetlink.schemas.errors import SchemaError
from fleetlink.schemas.typestore import load_typestore
from fleetlink.wire.calls import CallEnvelope, Outcome, OutcomeBatch, encode_outcomes, outcome_key
from fleetlink.wire.command_auth import key_id
from fleetlink.wire.commands import CommandEnvelope, CommandReply
from fleetlink.wire.keys import site_prefix

log = logging.getLogger(__name__)

__all__ = ["Repeater", "RepeaterStats"]


class Repeater:
    """One repeater process: takes commands and calls from the uplink over Zenoh and repeats or runs them
    near the robots. Start it with :meth:`start` (or ``with``), end it with :meth:`stop`."""

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
        self._shared = Shared(
            site=self.site,
            id=self.id,
            clock=clock,
            schedule=Schedule(dead_man=config.repeater.dead_man),
            store=CommandStore(config.repeater.state_dir),
        )
        self.stats: RepeaterStats = self._shared.stats
        self.schedule = self._shared.schedule
        self.store = self._shared.store
        self._subscribers = SubscriberWatch(self._shared.poke)
        self._loop = PublishLoop(self._shared, self._subscribers)
        self._intake: Intake | None = None
        self._session: zenoh.Session | None = None
        self._node: RosNode | None = None
        self._watcher: GraphWatcher | None = None
        self._queryable: Any = None
        self.calls = CallStore(config.repeater.state_dir)
        self._call_link: StatusLink | None = None
        self._runner: CallRunner | None = None
        self._call_queryable: Any = None
        self.call_intake: CallIntake | None = None
        self.feedback_dropped = 0
        self.metrics: PrometheusMetrics | NullMetrics = (
            PrometheusMetrics("repeater") if config.metrics is not None else NullMetrics()
        )
        self._metrics_server: HttpServer | None = None
        self.telemetry = RepeaterTelemetry(self.metrics)
        self.link_up: bool | None = None
        """Whether an uplink answers the status link (``None`` until the first answer or failure)."""

    # -- lifecycle ------------------------------------------------------------------------

    def start(self) -> Repeater:
        """Load the message types, replay the journals, open the Zenoh session and the ROS node, and start
        serving commands and calls; returns the repeater.

        Raises ``RepeaterConfigError`` when the message types or the command keys cannot be loaded.
        """
        ros, cfg, shared = self.config.ros, self.config.repeater, self._shared
        try:
            typestore = load_typestore(ros.distro, ros.message_paths)
        except SchemaError as exc:
            raise RepeaterConfigError(f"ros.message_paths: cannot load message types: {exc}") from None
        intake = self._intake = Intake(
            shared,
            Converter(typestore, ros.distro),
            max_active=cfg.max_active,
            publish=self._loop.publish,
            keys=trusted_keys(cfg.command_keys),
            on_forged=self.metrics.on_forged_command,
        )
        self.store.open()
        with shared.lock:
            restore(shared, intake.check)
        self._session = open_session(ros_session_config(self._options))
        self._node = RosNode(
            "fleetlink_repeater",
            "/",
            domain_id=ros.domain_id,
            session=self._session,
            typestore=typestore,
            distro=ros.distro,
        ).start()
        shared.publishers = Publishers(self._node)
        self._watcher = GraphWatcher(
            self._session, ros.domain_id, listeners=(self._subscribers.on_graph,)
        ).start()
        link = shared.link = StatusLink(
            self._session,
            self.site,
            self.id,
            heartbeat=cfg.heartbeat,
            timeout=cfg.status_timeout,
            on_link=self._on_link,
            on_acked=self._on_acked,
        )
        for number, event in sorted(self.store.pending.items()):
            link.submit(number, event)
        link.start()
        self._loop.start()
        key = f"{site_prefix(self.site)}/command/**"
        self._queryable = self._session.declare_queryable(key, intake.on_query)
        if self.config.metrics is not None and isinstance(self.metrics, PrometheusMetrics):
            host, port = split_listen(self.config.metrics.listen)
            self._metrics_server = serve_metrics(host, port, self.metrics, self.health)
        self._start_calls(typestore)
        log.info("repeater %s serving %s (%d commands resumed)", self.id, key, len(self.schedule.active()))
        return self

    def _start_calls(self, typestore: Any) -> None:
        """Service calls and action goals: the outcome link, the runner, the queryable."""
        if self._session is None or self._node is None:
            raise RepeaterConfigError("repeater not started")
        cfg, shared = self.config.repeater, self._shared
        self.calls.open()
        self._call_link = StatusLink(
            self._session,
            self.site,
            self.id,
            heartbeat=cfg.heartbeat,
            timeout=cfg.status_timeout,
            on_link=lambda _up: None,
            on_acked=self._on_outcomes_acked,
            key=outcome_key(self.site, self.id),
            encode=lambda outcomes: encode_outcomes(OutcomeBatch(self.id, self.site, outcomes)),
            heartbeats=False,
        )
        for number, out in sorted(self.calls.pending.items()):
            self._call_link.submit(number, out)
        self._call_link.start()
        runner = self._runner = CallRunner(self._node, self._emit, clock=shared.clock)
        self.call_intake = CallIntake(
            shared,
            self.calls,
            typestore,
            run=runner.submit,
            emit=self._emit,
            keys=trusted_keys(cfg.command_keys),
            on_forged=self.metrics.on_forged_command,
        )
        self._restore_calls(runner)
        self._call_queryable = self._session.declare_queryable(
            f"{site_prefix(self.site)}/call/**", self.call_intake.on_query
        )

    def _restore_calls(self, runner: CallRunner) -> None:
        """Goals accepted before a restart are followed again; any other unfinished call is
        reported as an error (it may or may not have reached the robot: it is not made again)."""
        now = self._shared.clock()
        unfinished: list[CallEnvelope] = [c.envelope for c in self.calls.calls.values() if not c.done]
        for env in unfinished:
            if env.kind == "goal" and env.deadline_ms > now * 1000:
                runner.submit(env, resume=True)
                continue
            detail = "the repeater restarted during the call: it may or may not have reached the robot"
            self._emit(final_outcome(env, "error", detail, int(now * 1000)), True)

    def stop(self) -> None:
        """Stop taking commands and calls, stop every thread, client and publisher, then close the session
        and the journals."""
        shared = self._shared
        if self._call_queryable is not None:
            self._call_queryable.undeclare()
            self._call_queryable = None
        if self._runner is not None:
            self._runner.stop()
            self._runner = None
        if self._call_link is not None:
            self._call_link.stop()
            self._call_link = None
        self.calls.close()
        if self._metrics_server is not None:
            self._metrics_server.stop()
            self._metrics_server = None
        if self._queryable is not None:
            self._queryable.undeclare()
            self._queryable = None
        self._loop.stop()
        if shared.link is not None:
            shared.link.stop()
            shared.link = None
        if self._watcher is not None:
            self._watcher.stop()
            self._watcher = None
        with shared.lock:
            if shared.publishers is not None:
                shared.publishers.stop_all()
                shared.publishers = None
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

    # -- commands and the link ------------------------------------------------------------

    def accept(self, env: CommandEnvelope) -> CommandReply:
        """Apply one command envelope (call under the lock); publishes at once when applied."""
        if self._intake is None:
            raise RepeaterConfigError("repeater not started")
        return self._intake.accept(env)

    def _emit(self, out: Outcome, final: bool) -> None:
        """Journal an outcome (feedback only in memory) and queue it for the uplink."""
        link = self._call_link
        with self._shared.lock:
            if out.kind == "feedback" and link is not None and link.pending() >= MAX_PENDING_FEEDBACK:
                self.feedback_dropped += 1
                return
            out = replace(out, site=self.site)
            number = self.calls.outcome(out)
            if final:
                kind = {"reply": "service", "result": "goal", "cancel": "cancel"}[out.kind]
                self.calls.done((kind, out.call_id, out.robot))
                self.calls.forget_before(int(self._shared.clock() * 1000))
        if out.kind != "feedback":
            self.calls.sync()
        if link is not None:
            link.submit(number, out)

    def _on_outcomes_acked(self, numbers: list[int]) -> None:
        with self._shared.lock:
            self.calls.acked(numbers)

    def _on_acked(self, numbers: list[int]) -> None:
        with self._shared.lock:
            self.store.acked(numbers)

    def _on_link(self, up: bool) -> None:
        shared = self._shared
        self.link_up = up
        with shared.lock:
            if up:
                self.schedule.link_up()
            else:
                self.schedule.link_down(shared.clock())
        shared.poke.set()

    # -- views ----------------------------------------------------------------------------

    def health(self) -> Health:
        """Report the counters to the metrics and answer the repeater's health (``/health``)."""
        shared = self._shared
        with shared.lock:
            return self.telemetry.observe(
                shared.stats,
                link_up=self.link_up,
                active=len(self.schedule.active()),
                pending=self.pending_statuses(),
            )

    @property
    def metrics_url(self) -> str | None:
        """Where ``/metrics`` and ``/health`` are served, when configured."""
        return self._metrics_server.url if self._metrics_server is not None else None

    def subscribers(self, topic: str) -> int:
        """How many subscribers the ROS graph shows on ``topic``."""
        return self._subscribers.count(topic)

    def pending_statuses(self) -> int:
        """How many status events wait for the uplink's acknowledgement (0 before :meth:`start`)."""
        return self._shared.link.pending() if self._shared.link is not None else 0


MAX_PENDING_FEEDBACK = 1_000
"""Feedback waiting for the uplink at most; more is dropped (counted: ``feedback_dropped``)."""


def trusted_keys(paths: list[Path]) -> dict[bytes, Ed25519PublicKey]:
    """The public keys commands must be signed with, by key id (errors name the config key)."""
    keys: dict[bytes, Ed25519PublicKey] = {}
    for index, path in enumerate(paths):
        try:
            key = load_public_key(path)
        except FleetlinkError as exc:
            raise RepeaterConfigError(f"repeater.command_keys[{index}]: {exc}") from None
        keys[key_id(key)] = key
    return keys
