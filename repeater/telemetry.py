"""The repeater's counters -> metrics and health (pull model: runs when /metrics or /health is read).

``RepeaterTelemetry.observe(stats, link_up=..., active=...)`` reports the increase of the
repeater's running totals since the previous look (``fleetlink_commands_total{command,
outcome}``: ``published`` per ROS topic, repeats included; ``applied``, ``duplicate``,
``expired``, ``refused`` for commands taken), sets the link and active-command gauges and
answers the repeater's health: ``degraded`` (``uplink_unreachable``) while its status link
gets no answer. Called under the repeater's lock (the stats are read consistently).
"""

from __future__ import annotations

import threading

from fleetlink.common.metrics import CounterDeltas, Health, Metrics, Problem
from fleetlink.repeater.shared import RepeaterStats


class RepeaterTelemetry:
    """Turns the repeater's running totals into metrics and its health (thread-safe)."""

    def __init__(self, metrics: Metrics) -> None:
        self.metrics = metrics
        self._deltas = CounterDeltas()
        self._lock = threading.Lock()

    def observe(self, stats: RepeaterStats, *, link_up: bool | None, active: int, pending: int) -> Health:
        """Report what ``stats`` gained since the last call, set the gauges and return the health.

        ``link_up`` ``None`` (no answer yet) counts as up; while it is down, the health names the
        ``pending`` status events.
        """
        with self._lock:
            m, d = self.metrics, self._deltas.delta
            for topic, n in sorted(stats.by_topic.items()):
                m.on_command(topic, "published", d(("published", topic), n))
            m.on_command("", "applied", d(("applied",), stats.applied))
            m.on_command("", "duplicate", d(("duplicate",), stats.duplicates))
            expired = stats.expired_on_arrival + stats.superseded_on_arrival
            m.on_command("", "expired", d(("expired",), expired))
            refused = stats.rejected + stats.malformed + stats.need_schema
            m.on_command("", "refused", d(("refused",), refused))
            m.set_repeater(link_up=link_up is not False, active=active)
            problems = []
            if link_up is False:
                problems.append(
                    Problem(
                        component="link",
                        subject="uplink",
                        reason="uplink_unreachable",
                        detail=f"no uplink answers the status link; {pending} status event(s) wait",
                        severity="degraded",
                    )
                )
            health = Health.of(problems, active_commands=active, link_up=link_up)
            m.set_health(health.state)
            return health
