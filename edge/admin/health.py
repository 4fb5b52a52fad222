"""The edge's health from a snapshot (pure): which mappings are degraded and why.

Rules (thresholds in ``HealthRules``):

- failed: the agent reports a failure (spool unwritable, a worker stopped);
- degraded, per mapping: the runtime reports an issue (``unknown_type``, ``setup``), or the
  mapping dead-lettered records in the last minute (``dead_letters``);
- degraded, per buffer: filled over 80 % of its capacity (``spool_filling``), or appenders are
  blocked waiting for room (``spool_full``), or damage was found in it that no operator has
  acknowledged yet (``spool_damage``, until ``POST /spool/damage/acknowledge``);
- degraded: the WAN link is down (``wan_down``: records are held in the buffers);
- degraded: overloaded, samples wait longer than ``intake.lag_alarm`` between receipt and spool
  (``lagging``), or the intake is over 90 % full (``intake_full``: samples are being dropped,
  counted);
- degraded: the process holds more than the memory bound its configuration implies
  (``memory``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from fleetlink.common.metrics.health import Health, Problem
from fleetlink.edge.admin.backend import EdgeSnapshot


@dataclass(frozen=True, slots=True)
class HealthRules:
    """Thresholds of ``assess``: the fill ratio (0..1) that counts as ``spool_filling`` and how many
    seconds back dead letters count."""

    spool_fill: float = 0.8
    dead_letter_window_s: float = 60.0


def assess(
    snapshot: EdgeSnapshot,
    recent_dead_letters: Mapping[str, int],
    *,
    now_ms: int,
    robots: int,
    rules: HealthRules | None = None,
) -> Health:
    """The edge's health from ``snapshot``: every problem found, with the spool fill ratio per stream, the
    WAN link state and the number of robots. ``recent_dead_letters`` counts each mapping's dead letters
    within the rules' window; ``now_ms`` is wall-clock milliseconds."""
    rules = rules or HealthRules()
    problems: list[Problem] = []
    if snapshot.failure:
        problems.append(Problem("process", "edge", "failed", snapshot.failure, severity="failed"))
    for mapping in sorted(snapshot.issues):
        for issue in snapshot.issues[mapping]:
            problems.append(Problem("mapping", mapping, issue.reason, issue.detail))
    window = f"{rules.dead_letter_window_s:g} s"
    for mapping, count in sorted(recent_dead_letters.items()):
        if count > 0:
            problems.append(
                Problem(
                    "mapping",
                    mapping,
                    "dead_letters",
                    f"{count} record(s) dead-lettered in the last {window}",
                )
            )
    fill: dict[str, float] = {}
    for buffer in snapshot.buffers:
        stats = buffer.stats
        ratio = stats.bytes / buffer.capacity_bytes if buffer.capacity_bytes > 0 else 0.0
        fill[stats.stream] = round(ratio, 4)
        if stats.blocked_appenders > 0:
            problems.append(
                Problem(
                    "spool",
                    stats.stream,
                    "spool_full",
                    f"{stats.blocked_appenders} appender(s) wait for room",
                )
            )
        elif ratio >= rules.spool_fill:
            problems.append(
                Problem(
                    "spool",
                    stats.stream,
                    "spool_filling",
                    f"{ratio:.0%} of {buffer.capacity_bytes} bytes used; the oldest "
                    f"record is {stats.oldest_age_ms(now_ms) / 1000:.1f} s old",
                )
            )
        if stats.damage_unacknowledged > 0:
            problems.append(
                Problem(
                    "spool",
                    stats.stream,
                    "spool_damage",
                    _damage_detail(stats.damage_unacknowledged, snapshot),
                )
            )
    if snapshot.wan_link_up is False:
        held = sum(b.stats.depth for b in snapshot.buffers)
        problems.append(
            Problem(
                "wan",
                "uplink",
                "wan_down",
                f"the uplink does not answer; {held} record(s) held in the buffers",
            )
        )
    problems.extend(_intake_problems(snapshot))
    return Health.of(problems, spool_fill=fill, wan_link_up=snapshot.wan_link_up, robots=robots)


def _damage_detail(count: int, snapshot: EdgeSnapshot) -> str:
    found = [f for findings in snapshot.spool_damage.values() for f in findings]
    lost = sum(int(f.get("records", 0) or 0) for f in found)
    first = found[0] if found else None
    where = f"; first: {first.get('reason')} in {first.get('file')}" if first is not None else ""
    return (
        f"{count} damage finding(s) ({lost} record(s) lost){where}; see GET /spool/damage, "
        "then POST /spool/damage/acknowledge"
    )


def _intake_problems(snapshot: EdgeSnapshot) -> list[Problem]:
    intake = snapshot.intake
    out: list[Problem] = []
    if intake.lag_alarm_s > 0 and intake.lag_s > intake.lag_alarm_s:
        out.append(
            Problem(
                "intake",
                "edge",
                "lagging",
                f"samples wait {intake.lag_s:.1f} s between receipt and spool "
                f"(alarm at {intake.lag_alarm_s:g} s): the edge cannot keep up",
            )
        )
    if intake.max_samples and intake.queued >= 0.9 * intake.max_samples:
        out.append(
            Problem(
                "intake",
                "edge",
                "intake_full",
                f"{intake.queued} of {intake.max_samples} samples queued; {intake.dropped} dropped so far",
            )
        )
    if intake.bound_bytes and intake.rss_bytes > intake.bound_bytes:
        out.append(
            Problem(
                "process",
                "edge",
                "memory",
                f"resident memory {intake.rss_bytes >> 20} MiB exceeds the bound of "
                f"{intake.bound_bytes >> 20} MiB its configuration implies",
            )
        )
    return out
