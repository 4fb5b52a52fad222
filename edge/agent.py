"""The edge agent: one process per robot network, between its Zenoh router and the uplink.

    with EdgeAgent(load_config(EdgeConfig, path)) as agent:   # start(): sockets, files, threads
        ...                                                   # stop(): bounded, flushes the spool

Inside: one Zenoh session (the config's ``zenoh:`` section, command-line options on top) for
discovery, registration, the admin space and the WAN; the native data plane (a second session,
a client of the same router) receiving every mapped topic into one bounded intake; robot
registration (discovered or explicit) instantiating the robot types' mappings; one processing
thread (the general path: decode, stages, Avro, dead letters); the durable spool
(``at_least_once``) and the memory buffer (``best_effort``); one WAN sender per buffer. Nothing
opens a socket or a file before ``start``. See docs/edge.md.
"""

from __future__ import annotations

import dataclasses
import gc
import json
import logging
import threading
import time
from pathlib import Path
from types import TracebackType
from typing import Any

import zenoh

from fleetlink.common.objects import ObjectStore, ObjectStoreError
from fleetlink.common.zenoh_options import ZenohOptions
from fleetlink.edge.config import EARLY_MAX_BYTES, EARLY_MAX_SAMPLES, EdgeConfig
from fleetlink.edge.errors import MappingError
from fleetlink.edge.mapping import Delivery, MappingSpec, MappingTable
from fleetlink.edge.runtime.dataplane import NativeSource, python_config_json
from fleetlink.edge.runtime.early import EarlySamples
from fleetlink.edge.runtime.errors import RuntimeSetupError
from fleetlink.edge.runtime.intake import Intake
from fleetlink.edge.runtime.limits import RecordLimit
from fleetlink.edge.runtime.offloader import Offloader
from fleetlink.edge.runtime.outgoing import Outgoing
from fleetlink.edge.runtime.processor import Emit, Item, Processor
from fleetlink.edge.runtime.records import RecordMaker
from fleetlink.edge.runtime.registration import (
    EVENT_FINGERPRINT,
    EVENT_SCHEMA_JSON,
    Registrar,
    RobotChange,
    event_record,
)
from fleetlink.edge.runtime.robot_log import RobotLog
from fleetlink.edge.runtime.schema_book import SchemaBook
from fleetlink.edge.runtime.sender import SenderOptions, WanSender
from fleetlink.edge.runtime.subscriptions import SubscriptionManager
from fleetlink.edge.runtime.transport import ZenohTransport
from fleetlink.edge.runtime.types import TypeStoreCodecs, schema_distro
from fleetlink.edge.runtime.uplinks import Uplinks
from fleetlink.edge.spool import MemoryBuffer, RecordBuffer, Spool
from fleetlink.edge.spool.frames import HEADER_SIZE, SEGMENT_HEADER_SIZE
from fleetlink.roswire.attachment import AttachmentVersion
from fleetlink.roswire.errors import RobotError
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.robots import RobotType
from fleetlink.roswire.session import DEFAULT_ROUTER, open_session
from fleetlink.schemas.errors import SchemaError
from fleetlink.schemas.typestore import load_typestore
from fleetlink.wire import ingest_key

log = logging.getLogger(__name__)

_NS = 1_000_000_000
ROBOT_PRIME_S = 2.0
"""At start, how long the edge waits at most for the robots alive on the network (a liveliness
query the router answers at once)."""
_RECORD_MARGIN = 64 << 10
"""Room left in a spool frame for a record's topic, key and headers around its value."""


def edge_session_config(options: ZenohOptions) -> zenoh.Config:
    """The agent's session: what the options say; without a Zenoh config file the defaults are
    an rmw_zenoh-like peer of the router on localhost:7447 (a router listens, connects nowhere)."""
    if options.config_file is None:
        mode = options.mode or "peer"
        options = options.with_defaults(
            mode=mode,
            connect=() if mode == "router" else (DEFAULT_ROUTER,),
            listen=("tcp/127.0.0.1:0",) if mode == "peer" else (),
        )
    conf = options.to_config()
    if options.config_file is None:
        conf.insert_json5("timestamping/enabled", json.dumps(True))
        if options.mode == "router":  # the site's router: every ROS 2 process is a session of it
            for key, value in SITE_ROUTER_LIMITS.items():
                conf.insert_json5(key, json.dumps(value))
    return conf


SITE_ROUTER_LIMITS = {"transport/unicast/max_sessions": 20000, "transport/shared_memory/enabled": False}
"""A router-mode edge serves a whole site: zenoh's default of 1,000 sessions refuses a fleet of some
100 robots (each runs several ROS 2 processes), and with shared memory on, a router has counters
for only some 350 sessions on its own host (as in deploy/zenoh/edge-router.json5)."""


class EdgeAgent:
    """The edge agent: receives the mapped ROS topics, turns samples into records, spools them and sends
    them to the uplink; also registers robots and uploads claim-checked payloads."""

    def __init__(
        self,
        config: EdgeConfig,
        zenoh_options: ZenohOptions | None = None,
        *,
        stop_timeout_s: float = 5.0,
    ) -> None:
        self.config = config
        self.zenoh_options = config.zenoh.merged_with(zenoh_options or ZenohOptions())
        self.table: MappingTable = config.mapping_table()
        self.stop_timeout_s = stop_timeout_s
        self.intake: Intake[Item] = Intake()
        """Control items for the processing thread (registration events); samples go through the
        data plane's intake (the config's ``intake`` section)."""
        self._lock = threading.Lock()
        self._started = False
        self._session: zenoh.Session | None = None
        self._node: RosNode | None = None
        self._spool: Spool | None = None
        self._memory: MemoryBuffer | None = None
        self._book: SchemaBook | None = None
        self._maker: RecordMaker | None = None
        self._processor: Processor | None = None
        self._senders: dict[Delivery, WanSender] = {}
        self._uplinks: Uplinks | None = None
        self._subscriptions: SubscriptionManager | None = None
        self._source: NativeSource | None = None
        self._registrar: Registrar | None = None
        self._store: ObjectStore | None = None
        self._offloader: Offloader | None = None
        self.record_limit: RecordLimit | None = None
        """The largest Kafka record the uplink produces, as learned from its answers."""
        self.robot_errors = 0
        self.robot_log = RobotLog()
        """When each robot registered and how; each robot's last registration changes."""
        self._gc_before = gc.get_threshold()

    # -- lifecycle -------------------------------------------------------------------------------
    def start(self) -> EdgeAgent:
        """Load the type store, open the spool and the Zenoh session, start the data plane, the WAN
        senders, processing, registration and subscriptions (once); returns ``self``. On failure whatever
        had started is torn down again."""
        with self._lock:
            if self._started:
                return self
            try:
                self._start()
            except BaseException:
                self._teardown(0.0)
                raise
            self._started = True
            self._gc_before = gc_for_throughput()
        log.info(
            "edge %s of site %s started: %d mapping(s), %d robot type(s)",
            self.config.edge_id,
            self.config.site,
            len(self.table.list()),
            len(self.config.robot_types),
        )
        return self

    def _start(self) -> None:
        config = self.config
        distro = schema_distro(config.ros.distro)
        try:
            typestore = load_typestore(distro, config.ros.message_paths)
        except SchemaError as exc:
            raise RuntimeSetupError(f"ros.message_paths: {exc}") from None
        types = [self._robot_type(name, rt.match) for name, rt in config.robot_types.items()]
        codecs = TypeStoreCodecs(typestore, distro)
        spool_dir = Path(config.spool.dir)
        self._book = book = SchemaBook(spool_dir / "schemas").load()
        book.add(EVENT_FINGERPRINT, EVENT_SCHEMA_JSON)
        # records are kept and sent in groups that fill a WAN batch without passing its limits
        group_records, group_bytes = config.wan.batch_max_records, int(config.wan.batch_max_bytes)
        spool_options = dataclasses.replace(
            config.spool.options(), group_records=group_records, group_bytes=group_bytes
        )
        self._spool = Spool(spool_dir / "durable", spool_options, stream="durable").open()
        self._memory = MemoryBuffer(
            stream="memory",
            max_bytes=int(config.memory.max_bytes),
            max_records=config.memory.max_records,
            group_records=group_records,
            group_bytes=group_bytes,
        )
        buffers: dict[Delivery, RecordBuffer] = {"at_least_once": self._spool, "best_effort": self._memory}
        configured = config.wan.max_record_bytes
        self.record_limit = limit = RecordLimit(
            None if configured is None else int(configured), spool_dir
        ).load()
        frame_limit = (
            min(
                int(config.spool.segment_bytes) - SEGMENT_HEADER_SIZE - HEADER_SIZE,
                int(config.memory.max_bytes),
            )
            - _RECORD_MARGIN
        )
        self._maker = RecordMaker(
            site=config.site,
            edge_id=config.edge_id,
            match=self.table.match,
            types=codecs,
            dead_letter_topic=config.topics.dead_letter,
            max_value_bytes=max(frame_limit, 1024),
            on_schema=book.add,
            max_record_bytes=limit.value,
            oversize=config.wan.oversize,
            object_prefix=config.objects.prefix if config.objects is not None else "",
            awaits_robot=self.table.awaits_robot,
        )
        session_config = edge_session_config(self.zenoh_options)
        plane_config = python_config_json(session_config)
        # the edge's session first: a router-mode edge's data plane connects to its listeners
        self._session = session = open_session(session_config)
        self._source = source = NativeSource(
            plane_config,
            max_items=config.intake.max_samples,
            max_bytes=int(config.intake.max_bytes),
            max_value_bytes=self._maker.fast_value_limit,
            group_records=group_records,
            group_bytes=group_bytes,
            coalesce_s=config.intake.coalesce / 1e9,
            busy_coalesce_s=config.intake.busy_coalesce / 1e9,
        )
        limit.on_change(self._apply_record_limit)
        # what each publisher had in the spool when the last run stopped: its first sample now
        # tells what never reached the spool (lost_at_restart, docs/spool.md "Loss before the spool")
        source.seed(self._spool.marks())
        ingest = ingest_key(config.site, config.edge_id)
        self._uplinks = Uplinks(session, ingest)
        transport = ZenohTransport(session, ingest, uplinks=self._uplinks)
        options = SenderOptions.from_wan(config.wan)
        self._senders = {
            delivery: WanSender(
                buffer,
                transport.for_stream(delivery),
                book,
                site=config.site,
                edge_id=config.edge_id,
                options=options,
                on_limit=limit.learn,
                origin=exactly_once_origin(config, buffer),
            )
            for delivery, buffer in buffers.items()
        }
        senders = self._senders
        early = EarlySamples(
            config.registration.hold, max_samples=EARLY_MAX_SAMPLES, max_bytes=EARLY_MAX_BYTES
        )
        source.waiting = early.waiting
        self._processor = Processor(
            self.intake,
            self._maker,
            buffers,
            on_appended=lambda delivery, linger: senders[delivery].pump(linger),
            source=source,
            table_version=lambda: self.table.version,
            default_linger_s=options.linger_s,
            early=early,
        )
        if config.objects is not None:
            self._start_offloader(self._processor)
        attachment: AttachmentVersion = 1 if config.ros.attachment == "v1" else 2
        self._node = RosNode(
            "fleetlink_edge",
            "/",
            domain_id=config.ros.domain_id,
            session=session,
            typestore=typestore,
            distro=distro,
            attachment_version=attachment,
        ).start()
        self._subscriptions = SubscriptionManager(
            self._node, self.table, source, known_type=lambda t: _known(codecs, t)
        )
        registration = config.registration
        self._registrar = Registrar(
            self._node,
            types,
            self._on_robot,
            site=config.site,
            edge_id=config.edge_id,
            grace_s=registration.grace_period / _NS,
            discover=registration.discover,
            register_topic=registration.topic,
            clock_ms=lambda: time.time_ns() // 1_000_000,
        )
        self._processor.start()
        for sender in self._senders.values():
            sender.start()
        # robots alive now are registered before anything is received: a sample of a robot not
        # registered yet makes no record, and after a restart it would be lost without a count
        self._registrar.start()
        if registration.discover:
            self._registrar.prime(ROBOT_PRIME_S)
        self._subscriptions.start()

    def _start_offloader(self, processor: Processor) -> None:
        """The object store of claim checks: refused credentials or a missing bucket stop the
        start (naming ``objects``); a store that does not answer yet only warns (uploads wait)."""
        section = self.config.objects
        if section is None:
            return
        try:
            store = ObjectStore(section)
        except ObjectStoreError as exc:
            raise RuntimeSetupError(f"objects: {exc}") from None
        self._store = store
        try:
            if section.create_bucket:
                store.ensure_bucket()
            else:
                store.check()
        except ObjectStoreError as exc:
            if not exc.retriable:
                raise RuntimeSetupError(f"objects: {exc}") from None
            log.warning("objects: the object store does not answer yet (%s); uploads wait for it", exc)
        self._offloader = Offloader(
            self._store,
            processor.post,
            workers=section.workers,
            max_pending_bytes=int(section.max_pending_bytes),
            backoff_max_s=section.retry_backoff_max,
        ).start()
        processor.uploader = self._offloader

    def _apply_record_limit(self, max_record_bytes: int) -> None:
        """The uplink's limit changed (or is first known): the record maker and the data plane
        keep larger records off the WAN from now on."""
        maker = self._maker
        if maker is not None:
            maker.set_record_limit(max_record_bytes)
            if self._source is not None:
                self._source.max_value_bytes = maker.fast_value_limit

    @staticmethod
    def _robot_type(name: str, match: str) -> RobotType:
        try:
            return RobotType(name, match if match.startswith("/") else "/" + match)
        except RobotError as exc:
            raise RuntimeSetupError(f"robot_types.{name}.match: {exc}") from None

    def stop(self, timeout_s: float | None = None) -> None:
        """Stop receiving, spool what was received, give the senders up to ``timeout_s`` (default
        ``stop_timeout_s``) to deliver, close everything. Unsent spooled records stay on disk."""
        with self._lock:
            if not self._started:
                return
            self._started = False
            self._teardown(self.stop_timeout_s if timeout_s is None else timeout_s)
            gc_restore(self._gc_before)
        log.info("edge %s stopped", self.config.edge_id)

    def _teardown(self, timeout_s: float) -> None:
        if self._registrar is not None:
            self._registrar.stop()
        if self._subscriptions is not None:
            self._subscriptions.stop()
        if self._offloader is not None:  # its last results go to the processor, still taking them
            self._offloader.stop(timeout_s)
        self.intake.close()
        if self._processor is not None:
            self._processor.stop()
        if self._source is not None:
            self._source.close()
        for sender in self._senders.values():
            sender.request_stop(timeout_s)
        for sender in self._senders.values():
            sender.join()
        if self._node is not None:
            self._node.stop()
        if self._session is not None:
            try:
                self._session.close()
            except zenoh.ZError as exc:
                log.debug("closing the zenoh session: %s", exc)
        for buffer in (self._spool, self._memory):
            if buffer is not None:
                buffer.close()
        self._close_objects()
        self._registrar = None
        self._subscriptions = None
        self._processor = None
        self._source = None
        self._node = None
        self._session = None
        self._spool = None
        self._memory = None

    def _close_objects(self) -> None:
        if self._store is not None:
            self._store.close()
        self._store = None
        self._offloader = None

    def __enter__(self) -> EdgeAgent:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    @property
    def session(self) -> zenoh.Session:
        """The agent's Zenoh session; raises ``RuntimeSetupError`` when the agent is not started."""
        if self._session is None:
            raise RuntimeSetupError("the edge agent is not started")
        return self._session

    # -- robots and mappings ---------------------------------------------------------------------
    def _on_robot(self, change: RobotChange) -> None:
        try:
            if change.registered:
                self.table.add_robot(change.robot, change.robot_type)
            else:
                self.table.remove_robot(change.robot)
            self.robot_log.record(change)
        except MappingError as exc:
            self.robot_errors += 1
            log.warning("robot %s: %s", change.robot, exc)
        if self._subscriptions is not None:
            self._subscriptions.refresh()
        record = event_record(
            change, site=self.config.site, edge_id=self.config.edge_id, topic=self.config.topics.registrations
        )
        item = Emit((Outgoing.of("at_least_once", record),))
        if self._processor is not None:
            self._processor.post(item)
        else:
            self.intake.offer(item, force=True)

    def register_robot(self, robot_type: str, name: str) -> None:
        """Register a robot explicitly (as a message on the register topic would)."""
        if self._registrar is None:
            raise RuntimeSetupError("the edge agent is not started")
        self._registrar.register(robot_type, name)

    def add_mapping(self, spec: MappingSpec, robot_type: str | None = None) -> None:
        """Add a mapping at runtime (``MappingError`` if invalid); subscriptions follow."""
        self.table.add_mapping(spec, robot_type)
        if self._subscriptions is not None:
            self._subscriptions.refresh()

    def remove_mapping(self, name: str) -> bool:
        """Remove a mapping at runtime by name (subscriptions follow); False if there is none."""
        removed = self.table.remove_mapping(name)
        if removed and self._subscriptions is not None:
            self._subscriptions.refresh()
        return removed

    def reload(self, config: EdgeConfig) -> tuple[str, ...]:
        """Take the mappings and robot types of ``config`` (the rest needs a restart); returns
        the robots dropped because their type is gone."""
        gone = self.table.reload(config.robot_type_specs(), [m.spec() for m in config.mappings])
        if self._subscriptions is not None:
            self._subscriptions.refresh()
        return gone

    def spool_damage(self) -> list[dict[str, Any]]:
        """Every damage finding of the durable spool (acknowledged ones too)."""
        return [] if self._spool is None else [f.as_dict() for f in self._spool.damage()]

    def acknowledge_spool_damage(self) -> list[dict[str, Any]]:
        """An operator looked at the spool's damage findings: acknowledge them (the edge stops
        reporting ``degraded`` for them); returns them."""
        if self._spool is None:
            raise RuntimeSetupError("the edge agent is not started")
        return [f.as_dict() for f in self._spool.acknowledge_damage()]

    # -- state -----------------------------------------------------------------------------------
    def subscribed_topics(self) -> dict[str, str | None]:
        """Each subscribed topic -> the ROS type it is taken as (``None``: any); empty before ``start``."""
        return {} if self._subscriptions is None else self._subscriptions.topics()

    def robots(self) -> dict[str, str]:
        """The robots registered now: robot name -> robot type."""
        return self.table.robots()

    def snapshot(self) -> dict[str, Any]:
        """Every counter, as plain data (JSON-ready)."""
        out: dict[str, Any] = {
            "site": self.config.site,
            "edge_id": self.config.edge_id,
            "running": self._started,
            "robots": self.table.robots(),
            "intake": self._source.intake_stats() if self._source is not None else {},
            "robot_errors": self.robot_errors,
            "robot_details": self.robot_log.details(),
            "robot_history": self.robot_log.history(),
        }
        if self._processor is not None:
            out.update(self._processor.counters())
            out["intake"]["lag_ms"] = self._processor.lag_ns // 1_000_000
        out["memory"] = {"rss_bytes": resident_bytes(), "bound_bytes": self.config.memory_bound()}
        if self._uplinks is not None:
            out["uplinks"] = sorted(self._uplinks.live())  # the uplinks the streams are shared among
        if self._subscriptions is not None:
            out["subscriptions"] = self._subscriptions.snapshot()
            out["lost_before_spool"] = lost_before_spool(out["subscriptions"], self.table)
        if self._registrar is not None:
            out["registration"] = {
                "events": self._registrar.events,
                "bad_registrations": self._registrar.bad_registrations,
            }
        streams: dict[str, Any] = {}
        buffers: dict[Delivery, RecordBuffer | None] = {
            "at_least_once": self._spool,
            "best_effort": self._memory,
        }
        for delivery, buffer in buffers.items():
            if buffer is None:
                continue
            entry: dict[str, Any] = {"buffer": _stats_dict(buffer)}
            if isinstance(buffer, Spool):
                entry["damage"] = [f.as_dict() for f in buffer.damage() if f.acknowledged_ms is None]
            sender = self._senders.get(delivery)
            if sender is not None:
                entry["sender"] = sender.snapshot()
            streams[buffer.stream] = entry
        out["streams"] = streams
        if self.record_limit is not None:
            out["record_limit"] = {
                "max_record_bytes": self.record_limit.value,
                "learned": self.record_limit.learned,
                "configured": self.record_limit.configured,
            }
        if self._offloader is not None:
            out["objects"] = self._offloader.snapshot()
        if self._book is not None:
            out["schemas"] = {
                "known": len(self._book),
                "corrupt": self._book.corrupt,
                "write_errors": self._book.write_errors,
            }
        return out


def exactly_once_origin(config: EdgeConfig, buffer: RecordBuffer) -> int:
    """The origin the sender of ``buffer`` puts in its batches: the spool's own with ``spool.delivery:
    exactly_once``, else 0 (at-least-once; the memory buffer always)."""
    if config.spool.delivery == "exactly_once" and isinstance(buffer, Spool):
        return buffer.origin
    return 0


GC_THRESHOLD = (50_000, 20, 100)
"""Collection thresholds while an agent runs. With Python's default (700 net allocations per
young collection) a burst of 60,000 samples cost the edge 380 young, 35 middle and 2 full
collections, 130-240 ms: up to a quarter of its CPU, and pauses every record waited out. The
records and samples never form reference cycles: they go by reference counting alone."""


def gc_for_throughput() -> tuple[int, int, int]:
    """Freeze what exists (type store, codecs, config, Zenoh objects: they live as long as the
    process, and a full collection walking them paused everything for 30-40 ms) and raise the
    thresholds; returns the thresholds to restore (``gc_restore``)."""
    before = gc.get_threshold()
    gc.freeze()
    gc.set_threshold(*GC_THRESHOLD)
    return before


def gc_restore(threshold: tuple[int, int, int]) -> None:
    """Undo ``gc_for_throughput`` (an embedding process, or a test, may start agents again)."""
    gc.set_threshold(*threshold)
    gc.unfreeze()


def lost_before_spool(subscriptions: dict[str, Any], table: MappingTable) -> dict[str, dict[str, int]]:
    """Robot -> ROS topic -> samples lost before the spool across restarts (``lost_at_restart``
    of the subscriptions' counters); topics of no robot come under ``""``."""
    out: dict[str, dict[str, int]] = {}
    for topic, counters in subscriptions.items():
        lost = counters.get("lost_at_restart", 0) if isinstance(counters, dict) else 0
        if not lost:
            continue
        robots = {m.robot for m in table.match(topic) if m.robot}
        parts = topic.strip("/").split("/")
        robot = min(robots) if robots else parts[0] if len(parts) > 1 else ""  # (a robot gone since)
        out.setdefault(robot, {})[topic] = int(lost)
    return out


def resident_bytes() -> int:
    """This process's resident memory (0 where /proc is not there)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def _stats_dict(buffer: RecordBuffer) -> dict[str, Any]:
    return dataclasses.asdict(buffer.stats())


def _known(codecs: TypeStoreCodecs, typename: str) -> bool:
    try:
        codecs.codec(typename)
    except SchemaError:
        return False
    return True
