"""``HistorySampler``: every ``interval_s``, read each site as a page would and keep its figures
in a ``History`` (the last hour), whether or not a page is open.

Per site (``("site", <site>)``): records received and emitted by its mappings, filtered by their
stages, lost, dead-lettered, records Kafka acknowledged (every uplink), the spool backlog and
the age of its oldest record, per second or as counts. Per mapping (``("mapping", <site>,
<name>)``): received, emitted, filtered, lost, dead-lettered per second.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

from fleetlink.common.worker import Worker
from fleetlink.console.history import History, Key
from fleetlink.console.rates import RateBoard
from fleetlink.console.sources import Sites
from fleetlink.console.views import site_figures

log = logging.getLogger(__name__)

FIGURES = ("mappings",)
"""What the sampler reads of a site besides its ``status``: reading its robots and topics too (as a
page does) cost an edge of 1,000 robots some 5 % of a core and, holding the interpreter for tens of
milliseconds every 10 s, its records' latency (bench/bench_fleet.py)."""


def _sum(values: list[float | None]) -> float | None:
    known = [v for v in values if v is not None]
    return sum(known) if known else None


def site_points(view: dict[str, Any]) -> dict[Key, dict[str, float | None]]:
    """The points one site view gives (pure)."""
    site = str(view["site"])
    mappings = view.get("mappings") or []
    rates = [m.get("rates") or {} for m in mappings]
    backlog = (view.get("graph") or {}).get("backlog") or {}
    delivery = view.get("delivery") or {}
    points: dict[Key, dict[str, float | None]] = {
        ("site", site): {
            "received": _sum([r.get("received") for r in rates]),
            "emitted": _sum([r.get("emitted") for r in rates]),
            "filtered": _sum([r.get("filtered") for r in rates]),
            "lost": _sum([r.get("dropped") for r in rates]),
            "dead_lettered": _sum([r.get("dead_lettered") for r in rates]),
            "acked": delivery.get("rate") if view.get("delivery") is not None else None,
            "backlog": backlog.get("records"),
            "oldest_age_s": backlog.get("oldest_age_s"),
        }
    }
    for mapping, r in zip(mappings, rates, strict=True):
        points[("mapping", site, str(mapping.get("name")))] = {
            "received": r.get("received"),
            "emitted": r.get("emitted"),
            "filtered": r.get("filtered"),
            "lost": r.get("dropped"),
            "dead_lettered": r.get("dead_lettered"),
        }
    return points


class HistorySampler(Worker):
    """A thread that reads every site each ``interval_s`` (the history's step by default) and adds its
    points to ``history``."""

    def __init__(
        self,
        sites: Sites,
        history: History,
        *,
        interval_s: float | None = None,
        clock: Callable[[], float] = time.time,
    ) -> None:
        super().__init__("console-history")
        self.sites = sites
        self.history = history
        self.interval_s = interval_s if interval_s is not None else history.step_s
        self._clock = clock
        self._board = RateBoard(window_s=self.interval_s * 2.5, min_span_s=self.interval_s * 0.5)
        self.samples = 0

    def sample(self) -> None:
        """Read every site once and add its points (also what the thread does each interval)."""
        for summary in self.sites.sites():
            site = str(summary.get("site"))
            now = self._clock()
            parts = self.sites.read(site, FIGURES)
            view = site_figures(site, parts, self._board, now=now, delivery=self.sites.delivery(site))
            for key, values in site_points(view).items():
                self.history.add(key, values, now)
        self.samples += 1

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.sample()
            except Exception as exc:  # noqa: BLE001 - a failed read must not end the history
                log.warning("console history: reading the sites failed: %r", exc)
            self._stop.wait(self.interval_s)
