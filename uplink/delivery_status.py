"""``DeliveryStatus``: this uplink's delivery figures, answered per site over Zenoh.

One queryable on ``fleetlink/*/delivery/<uplink_id>``; a query on ``fleetlink/<site>/delivery/*``
(one site) or ``fleetlink/*/delivery/*`` (every site) gets one reply per site this uplink served,
each on its concrete key ``fleetlink/<site>/delivery/<uplink_id>``::

    {"uplink": "uplink-7f3a", "site": "warehouse-a", "at": 1760000000.0, "started_at": ...,
     "batches": {"ok": 635, "error": 2}, "records": 9120, "dead_lettered": 0,
     "topics": {"fleet.ir": 4560, ...},                 # records Kafka acknowledged, per topic
     "latency": {"batches": 58, "max_ms": 9.1, "samples_ms": [4.2, ...]}}   # the last minute

The figures are running totals since the uplink started; a console adds up every uplink's and
turns them into rates. They are counters only (no record content): like ``/metrics`` they need
no token. Keys under ``fleetlink/<site>/`` keep the per-site ACLs of docs/zenoh_routers.md: a
site's edge may read its own figures (its console's Kafka column), no other site's.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable

import zenoh

from fleetlink.common.pooled_queryable import PooledQueryable
from fleetlink.uplink.delivery_board import DeliveryBoard
from fleetlink.uplink.latency import DeliveryLatency
from fleetlink.wire.keys import delivery_key

log = logging.getLogger(__name__)

SAMPLES = 200
"""Latency samples per site and answer: enough for a fleet-wide median and 95th percentile."""


class DeliveryStatus:
    """Answers queries for this uplink's delivery figures: one reply per site it served, on that site's own
    key."""

    def __init__(
        self,
        uplink_id: str,
        board: DeliveryBoard,
        latency: DeliveryLatency,
        *,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.uplink_id = uplink_id
        self.board = board
        self.latency = latency
        self._clock = clock
        self.started_at = clock()
        self._queryable = PooledQueryable(self._answer, workers=1, name="uplink-delivery")
        self.answered = 0

    def start(self, session: zenoh.Session) -> DeliveryStatus:
        """Declare the queryable on ``fleetlink/*/delivery/<uplink_id>`` on ``session``; returns self."""
        self._queryable.start(session, f"fleetlink/*/delivery/{self.uplink_id}")
        return self

    def stop(self) -> None:
        """Undeclare the queryable and wait for the answers under way."""
        self._queryable.stop()

    def figures(self, site: str) -> dict[str, object] | None:
        """The reply for ``site``: its delivery totals and recent latencies, with the times in seconds
        since the epoch (None: a site this uplink never served)."""
        found = self.board.figures(site)
        if found is None:
            return None
        return {
            "uplink": self.uplink_id,
            "site": site,
            "at": self._clock(),
            "started_at": self.started_at,
            **found,
            "latency": self.latency.recent(site, SAMPLES),
        }

    def _answer(self, query: zenoh.Query) -> None:
        try:
            wanted = zenoh.KeyExpr(str(query.key_expr))
            for site in self.board.sites():
                key = delivery_key(site, self.uplink_id)
                if not wanted.intersects(zenoh.KeyExpr(key)):
                    continue
                figures = self.figures(site)
                if figures is not None:
                    query.reply(key, json.dumps(figures).encode())
            self.answered += 1
        except Exception as exc:  # noqa: BLE001 - one bad query must not kill the worker silently
            log.warning("delivery status query on %s failed: %r", query.key_expr, exc)
        finally:
            query.drop()
