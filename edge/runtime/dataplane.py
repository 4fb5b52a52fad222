"""The edge's receive path: every subscription through one native data plane (``fleetlink._native``).

One Zenoh session of its own (a client of the same router as the edge's session), any number of
subscriptions feeding one bounded intake (samples *and* bytes; what does not fit is dropped and
counted per subscription), no thread per subscription, and ``take()``, which turns what arrived
into spool record payloads without the GIL:

* a sample whose data key has a **plan** (every mapping of its topic on the fast path: no stages,
  no message fields in topic or key) is converted CDR -> Avro natively and written as the record
  payload each mapping's ``PayloadTemplate`` would write, grouped per delivery class;
* every other sample comes back raw: it is accepted here (``SampleAcceptor``: attachment, CDR
  header, data key; the sequence numbers were already followed natively) and goes through the
  general path (``RecordMaker.make``), which may make a plan for its key; that plan is then
  installed, so the key's next samples stay native.

Plans depend on the mapping table: when its ``version`` moves, every plan is forgotten and made
again from the next sample of each key. See docs/edge.md ("The receive path").
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import re
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import zenoh

from fleetlink._native import MISMATCH, DataPlane
from fleetlink.edge.mapping import Delivery
from fleetlink.edge.runtime.errors import RuntimeSetupError
from fleetlink.edge.runtime.fastpath import FastPlan
from fleetlink.edge.runtime.outgoing import MappingCounters
from fleetlink.edge.runtime.processor import Rejected, Taken
from fleetlink.edge.runtime.records import RecordMaker
from fleetlink.roswire.acceptance import SampleAcceptor
from fleetlink.roswire.errors import KeyParseError, RoswireError
from fleetlink.roswire.names import parse_data_key
from fleetlink.schemas.codec import Codec
from fleetlink.schemas.layout_program import layout_program

log = logging.getLogger(__name__)

COLLECT_S = 0.002
"""After a first sample, how long ``take`` waits for more (a sample waits at most this long), so
that a steady flow is taken a few ms' worth at a time and the per-take work is shared."""
BUSY_RATE = 1500.0
BUSY_COLLECT_S = 0.025
"""While samples arrive at ``BUSY_RATE`` a second or more (over the last 100 ms), ``take`` waits
until this long after the first: a take costs some 250 µs of the edge's CPU whatever it
holds (the spool write, waking the WAN sender, the threads taking turns on the GIL), a third of
the edge at 10,000 samples/s when it is taken every 3 ms (bench/bench_fleet.py). At 2,000
samples/s (200 robots, 5 topics each at 2 Hz) it took 330 times a second, 6 samples each: from 1,500/s
on, 40 takes a second, each a WAN batch of some 50 records (with ``intake.busy_coalesce``: 51
instead of 75 µs of edge CPU a record, p99 57 ms, docs/benchmarks.md). Below that rate the
latency is worth more (p99 ≤ 20 ms at 1,000 samples/s)."""
DATAPLANE_RUNTIME = (
    "(rx: (handover: app), tx: (handover: app), net: (handover: app), acc: (handover: app),"
    " app: (worker_threads: 1))"
)
"""The Zenoh runtime of the data plane's own session (a client of one router, receiving only):
every task on one thread. Its socket's readiness was seen by one runtime's thread and its
samples read on another's, a thread switch a sample (bench/bench_fleet.py)."""


@contextlib.contextmanager
def _environment(name: str, value: str) -> Iterator[None]:
    """``name=value`` in the environment while the body runs (the native session's Zenoh reads
    its runtime settings from the environment when it opens its first session)."""
    before = os.environ.get(name)
    os.environ[name] = value
    try:
        yield
    finally:
        if before is None:
            del os.environ[name]
        else:
            os.environ[name] = before


MAX_TOPICS = 65536
"""Data keys whose topic is remembered (a peer inventing keys is parsed every time)."""
DELIVERY_CODES: dict[Delivery, int] = {"at_least_once": 0, "best_effort": 1}
DELIVERIES: tuple[Delivery, ...] = ("at_least_once", "best_effort")
_ANY_HOST = re.compile(r"^(tcp|tls|udp|quic)/(0\.0\.0\.0|\[::\])(:\d+)$")


def dataplane_config(python_config: dict[str, Any]) -> dict[str, Any]:
    """The data plane's Zenoh config, from the edge session's (as JSON): a client of the router
    the robots' data flows through. A router-mode edge is that router itself (its listeners
    face the robots; what it connects to is the cloud, which carries no robot data), so the data
    plane connects to its own listeners; any other edge to the routers it connects to. The rest
    (TLS, timeouts) as configured. Raises ``RuntimeSetupError`` when there is nothing to connect
    to."""
    config: dict[str, Any] = json.loads(json.dumps(python_config))  # a deep copy
    own = [
        _loopback(endpoint)
        for endpoint in _endpoints(config.get("listen"))
        if not endpoint.endswith(":0") and not endpoint.startswith("unixsock")
    ]
    routers = list(_endpoints(config.get("connect")))
    connect = (own or routers) if config.get("mode") == "router" else (routers or own)
    if not connect:
        raise RuntimeSetupError(
            "zenoh: the edge's receive path needs a router to connect to: give zenoh.connect, "
            "or listen on a fixed port (not :0)"
        )
    config.pop("id", None)
    config["mode"] = "client"
    config["connect"] = {**(config.get("connect") or {}), "endpoints": connect}
    config["listen"] = {**(config.get("listen") or {}), "endpoints": []}
    scouting = config.setdefault("scouting", {})
    scouting.setdefault("multicast", {})["enabled"] = False
    scouting.setdefault("gossip", {})["enabled"] = False
    config.pop("plugins", None)
    return config


def _loopback(endpoint: str) -> str:
    """A listener on every interface, reached over loopback."""
    match = _ANY_HOST.match(endpoint)
    if match is None:
        return endpoint
    host = "127.0.0.1" if match[2].startswith("0") else "[::1]"
    return f"{match[1]}/{host}{match[3]}"


def _endpoints(section: object) -> Iterable[str]:
    if not isinstance(section, dict):
        return ()
    endpoints = section.get("endpoints")
    if isinstance(endpoints, dict):  # per mode: {"router": [...], "peer": [...]}
        values = [e for v in endpoints.values() if isinstance(v, list) for e in v]
        return [str(e) for e in values]
    return [str(e) for e in endpoints] if isinstance(endpoints, list) else ()


@dataclass(slots=True)
class _LaneInfo:
    counters: MappingCounters
    delivery: Delivery
    linger_s: float | None
    mismatch: bool


class NativeSource:
    """The data plane as the processor sees it. Thread-safety: ``take``, ``install`` and ``sync``
    from the processing thread only; ``subscribe``/``unsubscribe``/``wake``/stats from any."""

    def __init__(
        self,
        python_config: dict[str, Any],
        *,
        max_items: int,
        max_bytes: int,
        max_value_bytes: int,
        group_records: int = 2000,
        group_bytes: int = 1 << 20,
        coalesce_s: float = 0.0,
        busy_coalesce_s: float = 0.0,
    ) -> None:
        config = dataplane_config(python_config)
        try:
            with _environment(
                "ZENOH_RUNTIME", os.environ.get("FLEETLINK_DATAPLANE_RUNTIME", DATAPLANE_RUNTIME)
            ):
                self.plane = DataPlane(
                    None,
                    [(key, json.dumps(value)) for key, value in config.items()],
                    max_items,
                    max_bytes,
                    coalesce_s=coalesce_s,
                    busy_coalesce_s=busy_coalesce_s,
                )
        except (ValueError, RuntimeError) as exc:
            raise RuntimeSetupError(f"zenoh: the edge's receive path cannot start: {exc}") from None
        self.max_value_bytes = max_value_bytes
        self.group_records = group_records
        self.group_bytes = group_bytes
        self._receivers: dict[int, str] = {}  # sub id -> key expression
        self._next_sub = 1
        self._acceptor = SampleAcceptor(track_sequences=False)  # the sequences are followed natively
        self._rejected: dict[str, int] = {}  # topic -> samples refused on the general path
        self._unmapped: dict[str, int] = {}  # topic -> samples no mapping took on the general path
        self.waiting: Callable[[], Mapping[str, int]] = dict
        """Topic -> samples waiting for their robot's registration (``edge.runtime.early``)."""
        self._topics: dict[str, str] = {}  # data key -> topic (parsed once)
        self._programs: dict[int, int] = {}  # id(codec) -> program id
        self._codecs: list[Codec] = []  # keeps the codecs (and so their ids) alive
        self._lanes: list[_LaneInfo] = []
        self._lane_ids: dict[tuple[int, Delivery, float | None, bool], int] = {}
        self._installed: dict[str, FastPlan] = {}
        self._table_version: int | None = None

    # -- subscriptions (any thread) ---------------------------------------------------------------
    def subscribe(self, key_expr: str) -> int:
        """Receive every sample on ``key_expr`` (wildcards welcome: one key for a whole fleet)."""
        sub_id = self._next_sub
        self._next_sub += 1
        self._receivers[sub_id] = key_expr
        self.plane.subscribe(sub_id, key_expr, key_expr)
        return sub_id

    def unsubscribe(self, sub_id: int) -> None:
        """Stop receiving on the subscription ``sub_id``."""
        self.plane.unsubscribe(sub_id)
        self._receivers.pop(sub_id, None)

    def wake(self) -> None:
        """Make a ``take`` that waits return now."""
        self.plane.wake()

    def close(self) -> None:
        """Close the data plane and its Zenoh session; nothing is received afterwards."""
        self.plane.close()

    # -- the processing thread --------------------------------------------------------------------
    def take(self, max_samples: int, timeout_s: float) -> Taken:
        """Take up to ``max_samples``, waiting up to ``timeout_s`` seconds for the first: records made
        natively, grouped per delivery class, and the samples left for the general path (a sample the
        acceptor refuses comes as ``Rejected`` and is counted per topic). Updates the lanes' counters."""
        groups, slow, lanes, count, oldest, marks = self.plane.take(
            max_samples,
            timeout_s,
            self.max_value_bytes,
            self.group_records,
            self.group_bytes,
            COLLECT_S,
            BUSY_RATE,
            BUSY_COLLECT_S,
        )
        taken = Taken(count=count, oldest_received_ns=oldest, marks=marks)
        for code, group in groups:
            taken.groups.setdefault(DELIVERIES[code], []).append(group)
        infos = self._lanes
        for lane_id, received, emitted in lanes:
            info = infos[lane_id]
            info.counters.received += received
            if info.mismatch:
                info.counters.type_mismatch += received
                continue
            info.counters.emitted += emitted
            shortest = taken.lingers.get(info.delivery, info.linger_s)
            if info.linger_s is not None and (shortest is None or info.linger_s < shortest):
                shortest = info.linger_s
            taken.lingers[info.delivery] = shortest
        accept = self._acceptor.accept
        for sub_id, key, payload, attachment, received_ns in slow:
            try:
                taken.samples.append(accept(key, payload, attachment, received_ns))
            except RoswireError as exc:
                topic = self.topic_of(key) or self._receivers.get(sub_id, "")
                self._rejected[topic] = self._rejected.get(topic, 0) + 1
                taken.samples.append(Rejected(topic, exc, received_ns))
        return taken

    def topic_of(self, key: str) -> str | None:
        """The ROS topic of a data key (``None`` when it is not one)."""
        topic = self._topics.get(key)
        if topic is None:
            try:
                topic = parse_data_key(key).topic
            except KeyParseError:
                return None
            if len(self._topics) < MAX_TOPICS:
                self._topics[key] = topic
        return topic

    def seed(self, marks: Iterable[tuple[bytes, int]]) -> None:
        """What a previous run spooled last per publisher GID (see ``DataPlane.seed``)."""
        self.plane.seed(list(marks))

    def sync(self, table_version: int) -> None:
        """Forget every plan when the mapping table changed since the last call."""
        if table_version != self._table_version:
            if self._table_version is not None:
                self.plane.clear_plans()
                self._installed.clear()
                self._lanes.clear()
                self._lane_ids.clear()
            self._table_version = table_version

    def install(self, maker: RecordMaker, keys: Iterable[str]) -> None:
        """Hand the fast plans the general path made for ``keys`` to the data plane."""
        self._unmapped = maker.unmapped
        for key in keys:
            plan = maker.plan_for(key)  # lanes () when no mapping takes the key: dropped natively
            if plan is None or plan.lanes is None or self._installed.get(key) is plan:
                continue
            lanes: list[tuple[int, int, bytes, bytes, int, int]] = []
            for counters in plan.mismatched:
                lanes.append(
                    (self._lane(_LaneInfo(counters, "at_least_once", None, True)), MISMATCH, b"", b"", 0, 0)
                )
            for lane in plan.lanes:
                info = _LaneInfo(lane.counters, lane.delivery, lane.linger_s, False)
                lanes.append(
                    (
                        self._lane(info),
                        self._program(lane.codec),
                        lane.head,
                        lane.template.tail,
                        lane.template.flags,
                        DELIVERY_CODES[lane.delivery],
                    )
                )
            if self.plane.set_plan(key, lanes):
                self._installed[key] = plan

    def _lane(self, info: _LaneInfo) -> int:
        """The lane id counting into ``info`` (one for every key that counts alike, so that a take
        reports a few lanes, not one per robot)."""
        same = (id(info.counters), info.delivery, info.linger_s, info.mismatch)
        lane = self._lane_ids.get(same)
        if lane is None:
            lane = self._lane_ids[same] = len(self._lanes)
            self._lanes.append(info)
        return lane

    def _program(self, codec: Codec) -> int:
        program = self._programs.get(id(codec))
        if program is None:
            program = len(self._codecs)
            self.plane.add_program(program, layout_program(codec.layout))
            self._codecs.append(codec)
            self._programs[id(codec)] = program
        return program

    # -- state (any thread) -----------------------------------------------------------------------
    def intake_stats(self) -> dict[str, int]:
        """The intake's counters, in the shape the edge has always reported (``offered`` …)."""
        stats = self.plane.stats()
        offered = sum(received for received, _dropped in self.plane.sub_stats().values())
        return {
            "offered": offered,
            "taken": int(stats["taken"]),
            "coalesced": int(stats["coalesced"]),
            "dropped": int(stats["dropped"]),
            "dropped_bytes": int(stats["dropped_bytes"]),
            "queued": int(stats["queued"]),
            "queued_bytes": int(stats["queued_bytes"]),
            "high_water": int(stats["high_water"]),
            "max_items": int(stats["max_items"]),
            "max_bytes": int(stats["max_bytes"]),
            "oldest_queued_ns": int(stats["oldest_ns"]),
        }

    def receiver_stats(self) -> dict[str, dict[str, int]]:
        """Per key expression received on: samples that arrived, and those dropped at the intake."""
        native = self.plane.sub_stats()
        return {
            key_expr: dict(zip(("received", "dropped"), native.get(sub_id, (0, 0)), strict=True))
            for sub_id, key_expr in sorted(self._receivers.items(), key=lambda item: item[1])
        }

    def topic_stats(self) -> dict[str, dict[str, int]]:
        """Per ROS topic that sent anything: samples taken, refused, unmapped (no mapping took them:
        no record), waiting (for their robot's registration), and what the publishers' sequence
        numbers say (gaps, missing: lost before the edge saw them; duplicates)."""
        out: dict[str, dict[str, int]] = {}
        names = ("received", "gaps", "missing", "duplicates", "lost_at_restart", "unmapped")
        for key, counts in self.plane.key_stats().items():
            topic = self.topic_of(key) or key
            entry = out.setdefault(topic, dict.fromkeys(names, 0))
            for name, value in zip(names, counts, strict=True):
                entry[name] += value
        waiting = self.waiting()
        for entry_topic, entry in out.items():
            rejected = self._rejected.get(entry_topic, 0)
            entry["rejected"] = rejected
            entry["unmapped"] += self._unmapped.get(entry_topic, 0)
            entry["waiting"] = waiting.get(entry_topic, 0)
            entry["delivered"] = entry["received"] - rejected - entry["unmapped"] - entry["waiting"]
        return out


def python_config_json(config: zenoh.Config) -> dict[str, Any]:
    """A session config as plain data (what ``dataplane_config`` reads)."""
    data = json.loads(str(config))
    if not isinstance(data, dict):
        raise RuntimeSetupError("zenoh: the session config is not an object")
    return data
