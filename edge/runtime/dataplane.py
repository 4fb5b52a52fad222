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

import json
import logging
import re
from collections.abc import Iterable
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
from fleetlink.roswire.errors import RoswireError
from fleetlink.schemas.codec import Codec
from fleetlink.schemas.layout_program import layout_program

log = logging.getLogger(__name__)

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


@dataclass(slots=True)
class _Subscription:
    topic: str
    acceptor: SampleAcceptor
    rejected: int = 0


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
    ) -> None:
        config = dataplane_config(python_config)
        try:
            self.plane = DataPlane(
                None, [(key, json.dumps(value)) for key, value in config.items()], max_items, max_bytes
            )
        except (ValueError, RuntimeError) as exc:
            raise RuntimeSetupError(f"zenoh: the edge's receive path cannot start: {exc}") from None
        self.max_value_bytes = max_value_bytes
        self.group_records = group_records
        self.group_bytes = group_bytes
        self._subs: dict[int, _Subscription] = {}
        self._next_sub = 1
        self._programs: dict[int, int] = {}  # id(codec) -> program id
        self._codecs: list[Codec] = []  # keeps the codecs (and so their ids) alive
        self._lanes: list[_LaneInfo] = []
        self._installed: dict[str, FastPlan] = {}
        self._table_version: int | None = None
        self._orphans = _Subscription("", SampleAcceptor(track_sequences=False))
        """For samples of a subscription already forgotten (made into records all the same)."""

    # -- subscriptions (any thread) ---------------------------------------------------------------
    def subscribe(self, topic: str, key_expr: str) -> int:
        sub_id = self._next_sub
        self._next_sub += 1
        self._subs[sub_id] = _Subscription(topic, SampleAcceptor(track_sequences=False))
        self.plane.subscribe(sub_id, key_expr, topic)
        return sub_id

    def unsubscribe(self, sub_id: int) -> None:
        self.plane.unsubscribe(sub_id)
        self._subs.pop(sub_id, None)

    def wake(self) -> None:
        self.plane.wake()

    def close(self) -> None:
        self.plane.close()

    # -- the processing thread --------------------------------------------------------------------
    def take(self, max_samples: int, timeout_s: float) -> Taken:
        groups, slow, lanes, count, oldest = self.plane.take(
            max_samples, timeout_s, self.max_value_bytes, self.group_records, self.group_bytes
        )
        taken = Taken(count=count, oldest_received_ns=oldest)
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
        for sub_id, key, payload, attachment, received_ns in slow:
            sub = self._subs.get(sub_id) or self._orphans
            try:
                taken.samples.append(sub.acceptor.accept(key, payload, attachment, received_ns))
            except RoswireError as exc:
                sub.rejected += 1
                taken.samples.append(Rejected(sub.topic, exc, received_ns))
        return taken

    def sync(self, table_version: int) -> None:
        """Forget every plan when the mapping table changed since the last call."""
        if table_version != self._table_version:
            if self._table_version is not None:
                self.plane.clear_plans()
                self._installed.clear()
                self._lanes.clear()
            self._table_version = table_version

    def install(self, maker: RecordMaker, keys: Iterable[str]) -> None:
        """Hand the fast plans the general path made for ``keys`` to the data plane."""
        for key in keys:
            plan = maker.plan_for(key)
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
            self.plane.set_plan(key, lanes)
            self._installed[key] = plan

    def _lane(self, info: _LaneInfo) -> int:
        self._lanes.append(info)
        return len(self._lanes) - 1

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
        per_sub = self.plane.sub_stats()
        offered = sum(received for received, *_ in per_sub.values())
        return {
            "offered": offered,
            "taken": int(stats["taken"]),
            "dropped": int(stats["dropped"]),
            "dropped_bytes": int(stats["dropped_bytes"]),
            "queued": int(stats["queued"]),
            "queued_bytes": int(stats["queued_bytes"]),
            "high_water": int(stats["high_water"]),
            "max_items": int(stats["max_items"]),
            "max_bytes": int(stats["max_bytes"]),
            "oldest_queued_ns": int(stats["oldest_ns"]),
        }

    def subscription_stats(self, sub_id: int) -> dict[str, int]:
        received, dropped, gaps, missing, duplicates = self.plane.sub_stats().get(sub_id, (0, 0, 0, 0, 0))
        sub = self._subs.get(sub_id)
        rejected = sub.rejected if sub is not None else 0
        return {
            "received": received,
            "delivered": received - dropped - rejected,
            "rejected": rejected,
            "dropped": dropped,
            "gaps": gaps,
            "missing": missing,
            "duplicates": duplicates,
        }


def python_config_json(config: zenoh.Config) -> dict[str, Any]:
    """A session config as plain data (what ``dataplane_config`` reads)."""
    data = json.loads(str(config))
    if not isinstance(data, dict):
        raise RuntimeSetupError("zenoh: the session config is not an object")
    return data
